from learning.startup import quiet_ctrl_c_at_startup

quiet_ctrl_c_at_startup()  # `python -m analysis.<module>` imports this package first, before torch and MuJoCo
