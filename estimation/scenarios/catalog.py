"""The scenario catalog: every named scenario (:func:`scenarios`) and the look-up by name
(:func:`get_scenario`)."""

from __future__ import annotations

from estimation.errors import ConfigError
from estimation.plants.torque_params import DieselRigParams
from estimation.scenarios.airpath import maf_scenario
from estimation.scenarios.base import Scenario
from estimation.scenarios.nox import nox_scenario
from estimation.scenarios.skf_sim import skf_sim_scenario
from estimation.scenarios.torque import torque_scenario


def _rig_description(p: DieselRigParams) -> str:
    """What ``torque-rig`` simulates, in the numbers of its plant's parameters."""
    low, high = p.sweep_speed_range_rpm
    return (
        f"Diesel engine on a dynamometer: chirp speed sweep {low:.0f}–{high:.0f} rpm, torque "
        f"demand steps and ramps of {min(p.demand_torques_nm):.0f}–"
        f"{max(p.demand_torques_nm):.0f} N·m (TQ §VII); the rig's encoder noise "
        f"(σ = {p.speed_noise_std_rpm:.1f} rpm) on the speed and its load cell's "
        f"(σ = {p.load_noise_std_nm:.1f} N·m) on the load."
    )


def _catalog() -> dict[str, Scenario]:
    scenarios = [
        skf_sim_scenario(1),
        skf_sim_scenario(2),
        skf_sim_scenario(3),
        nox_scenario(
            "nox-sdmp",
            "sdmp",
            "Engine-out NOx map (12×18, SKF (34)) drifting slowly, seen through a 0.75 s delay "
            "and a = 0.96 lag, on a sportive mountain drive with sharp load and speed changes.",
            1200.0,
        ),
        nox_scenario(
            "nox-nedc",
            "nedc",
            "The same NOx map and sensor on the slow NEDC: poorer excitation (SKF §6.4).",
            1180.0,
        ),
        maf_scenario(
            "maf-whtc",
            "whtc",
            "2d",
            "2.0 L diesel air path (EGR, VGT) on the WHTC (standing in for the ETC) with an "
            "additive MAF error map ΔW_c(u_δ, n_e) on the LPV grid 0:4:56 mg × 0:250:3000 rpm; "
            "sensors logged at 10 Hz as the mean of ten 10 ms ECU readings.",
            1800.0,
        ),
        maf_scenario(
            "maf-ftp75",
            "ftp75",
            "2d",
            "The same air path, MAF error map and sensors on the FTP-75 (LPV §4's second case).",
            1874.0,
        ),
        maf_scenario(
            "maf-1d-whtc",
            "whtc",
            "1d",
            "The air path on the WHTC with a relative MAF error W_meas = (1 + q(W))·W, q a 1-D "
            "map over W (EKF (6), §5).",
            1800.0,
        ),
        torque_scenario(
            "torque-si",
            "2.0 L SI engine mean value model (TQ (1)–(8)) with firing ripple under a speed "
            "profile 2200→2500→2200→1900 rpm (TQ §VI); noise N(0, 20) on speed and load.",
            (("speed_rpm", "rpm"), ("load_torque_nm", "N·m"), ("air_mass_flow_kg_s", "kg/s")),
        ),
        torque_scenario(
            "torque-rig",
            _rig_description(DieselRigParams()),
            (("speed_rpm", "rpm"), ("load_torque_nm", "N·m"), ("air_mass_flow_kg_s", "kg/s")),
        ),
    ]
    return {s.name: s for s in scenarios}


def scenarios() -> dict[str, Scenario]:
    """Every scenario by name."""
    return _catalog()


def get_scenario(name: str) -> Scenario:
    catalog = _catalog()
    try:
        return catalog[name]
    except KeyError:
        raise ConfigError(f"unknown scenario {name!r}; choose one of {sorted(catalog)}") from None
