from setuptools import find_packages, setup

setup(
    name="orcgym",
    version="0.1.0",
    description="Emergent quadruped gaits with decentralized phase oscillators: MuJoCo + rsl-rl-lib",
    license="BSD-3-Clause",
    python_requires=">=3.10",
    packages=find_packages(include=["gym_envs*", "learning*", "analysis*"]),
    py_modules=["train", "play", "sweep"],
    include_package_data=True,
    package_data={"": ["*.xml"]},
    install_requires=[
        "torch>=2.2,<3",
        "rsl-rl-lib>=5.5,<5.6",  # learning/runner.py overrides internals; tests/test_rsl_rl_contract.py checks them
        "mujoco>=4.0,<5",
        "numpy>=1.24",
        "pyyaml>=6",
        "tensorboard>=2.14",
        "matplotlib>=3.7",
        "onnx>=1.16",
        "onnxruntime>=1.17",
        "imageio>=2.31",
        "imageio-ffmpeg>=0.4.9",
        "tqdm>=4.60,<5",
    ],
    extras_require={
        "test": ["pytest>=7"],
        "gpu": ["warp-lang>=1.9", "mujoco-warp>=4.0"],
        "wandb": ["wandb>=0.17"],  # train.py --logger wandb
        "neptune": ["neptune>=1.0"],  # train.py --logger neptune
    },
)
