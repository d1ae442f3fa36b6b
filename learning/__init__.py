"""Learning side of orcgym: rsl-rl-lib PPO on gym_envs tasks.

runner_config: typed train configs per task, profiles, the rsl-rl dict; vec_env: the VecEnv
adapter; runs: run folders and checkpoints; runner: the OnPolicyRunner subclass used by
train.py and play.py; machine: training defaults that fit the machine; distributed: ranks,
process group and thread shares under torchrun; video: clips of robot 0; export: the deployable
policy and controller; cli: the flags, checks and error path every command line shares.
This package may import gym_envs; gym_envs never imports it.
"""
