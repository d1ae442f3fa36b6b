import os

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(REPO, "resources", "robots", "mini_cheetah", "scene.xml")
FOOT_SENSORS = ("RF_foot_force", "LF_foot_force", "RH_foot_force", "LH_foot_force")


@pytest.fixture
def make_sim():
    """A small CPU batch of the Mini Cheetah scene."""
    from gym_envs.sim import make_backend

    def build(num_envs=4, num_threads=1, **kwargs):
        return make_backend(
            "mujoco",
            model_path=kwargs.pop("model_path", SCENE),
            num_envs=num_envs,
            foot_sensors=FOOT_SENSORS,
            termination_sensors=("base_force",),
            num_threads=num_threads,
            **kwargs,
        )

    return build
