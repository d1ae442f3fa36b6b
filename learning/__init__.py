"""Learning side of orcgym: rsl-rl-lib PPO on gym_envs tasks.

runner_config: typed train configs per task, profiles, the rsl-rl dict; vec_env: the VecEnv
adapter; runs: run folders and checkpoints; runner: the OnPolicyRunner subclass used by
train.py and play.py; distributed: ranks, process group and thread shares under torchrun.
This package may import gym_envs; gym_envs never imports it.
"""
