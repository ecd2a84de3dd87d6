"""The scenario catalog: every named scenario (:func:`scenarios`) and the look-up by name
(:func:`get_scenario`)."""

from __future__ import annotations

from estimation.errors import ConfigError
from estimation.scenarios.airpath import maf_scenario
from estimation.scenarios.base import Scenario
from estimation.scenarios.nox import nox_scenario
from estimation.scenarios.skf_sim import skf_sim_scenario
from estimation.scenarios.torque import torque_scenario


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
            # The plant's own numbers (DieselRigParams; a test holds them equal): the catalog
            # is served by the API process, which must not import the plants' numba kernels.
            "Diesel engine on a dynamometer: chirp speed sweep 1000–2500 rpm, torque demand "
            "steps and ramps of 30–280 N·m (TQ §VII); the rig's encoder noise (σ = 4.2 rpm) "
            "on the speed and its load cell's (σ = 0.5 N·m) on the load.",
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
