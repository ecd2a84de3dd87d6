"""Names of the channels a torque log carries (TQ Table I), shared by the torque simulators
(:mod:`estimation.plants.torque`) and the estimators (:mod:`estimation.torque`)."""

SPEED_CHANNEL = "speed_rpm"
"""Engine speed N [rpm]."""
LOAD_CHANNEL = "load_torque_nm"
"""Load (dynamometer) torque τ_l [N·m]."""
AIR_CHANNEL = "air_mass_flow_kg_s"
"""Intake air mass flow ṁ_ai [kg/s]."""
