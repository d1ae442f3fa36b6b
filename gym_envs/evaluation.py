"""The evaluation setting of a task: what play.py, the analysis and the benchmarks roll policies out in.

A fixed command that is never resampled, no time-outs, and every training randomness off unless
asked for: observation noise, oscillator noise (process noise and the omega/sigma jitter), pushes,
domain randomisation with randomised resets, and episodes drawn without coupling. Returned as
`section.key=value` overrides so a run's saved config turns into its evaluation config with
`gym_envs.config.apply_overrides`.
"""

from __future__ import annotations


def evaluation_overrides(
    cfg,
    command: tuple[float, float, float] = (0.0, 0.0, 0.0),
    observation_noise: bool = False,
    oscillator_noise: bool = False,
    pushes: bool = False,
    randomize: bool = False,
) -> list[str]:
    vx, vy, yaw = (float(c) for c in command)
    items = [
        "env.episode_length_s=1.0e9",
        "commands.resampling_time_s=1.0e9",
        "commands.lin_vel_x_choices=[]",
        "commands.lin_vel_x_noise=0.0",
        f"commands.lin_vel_x=[{vx!r}, {vx!r}]",
        f"commands.lin_vel_y=[{vy!r}, {vy!r}]",
        f"commands.yaw_rate=[{yaw!r}, {yaw!r}]",
        "commands.small_command_norm=0.0",
        "commands.zero_lateral_and_yaw_prob=0.0",
        "commands.zero_planar_prob=0.0",
        "commands.zero_all_prob=0.0",
    ]
    if not observation_noise:
        items.append("observations.noise_scale=0.0")
    if not oscillator_noise and hasattr(cfg, "osc"):
        items += ["osc.process_noise_std=0.0", "osc.omega_noise_std=0.0", "osc.coupling_noise_std=0.0"]
    if not pushes:
        items.append("push.enabled=false")
    if not randomize:
        items += [
            "domain_rand.randomize_friction=false",
            "domain_rand.randomize_base_mass=false",
            "domain_rand.randomize_base_com=false",
            "init_state.mode=default",
        ]
        if hasattr(cfg, "osc"):
            # Episodes drawn with sigma = 0 are a training randomisation, in either stage.
            items += ["osc.coupling_off_prob=0.0", "osc.second_stage.start_step=0"]
    return items
