"""What the four papers publish, as constants, each with its table/figure reference.

Only the papers' numbers and claims live here; every number of ours is computed live by
``mapwise reproduce``. The papers **SKF**, **LPV**, **EKF** and **TQ** are cited in full in
docs/algorithms.md#papers.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

# --- SKF paper §5: synthetic checks ----------------------------------------------------------

SKF_SIM_REFS: Final = MappingProxyType(
    {1: "SKF §5.1, Figs. 6–8", 2: "SKF §5.2, Figs. 9–11", 3: "SKF §5.3, Figs. 12–13"}
)
SKF_SIM_CONVERGES: Final = MappingProxyType(
    {
        # SKF §5.1: "All three methods perform well".
        1: MappingProxyType({"kf": True, "skf": True, "sskf": True}),
        # SKF §5.2: KF and SKF converge on the 8 excited elements; "SSKF estimation does not
        # converge for x6, x7 and x8".
        2: MappingProxyType({"kf": True, "skf": True, "sskf": False}),
        # SKF §5.3: "KF and SKF performs well, being able to also filter the noise, but SSKF
        # is not capable of converging again".
        3: MappingProxyType({"kf": True, "skf": True, "sskf": False}),
    }
)
SKF_SIM_CLAIMS: Final = MappingProxyType(
    {
        1: "All three methods converge on the whole 4×4 table (Fig. 7: mean of all states); "
        "KF and SKF variances of x6 differ for a while, then agree (Fig. 8).",
        2: "KF and SKF converge on the 8 excited elements x5…x12 after the return sweep; "
        "their variances are similar 'although some deviation exists in elements 6 and 7' "
        "(Fig. 10); SSKF does not converge for x6, x7, x8 (Fig. 9).",
        3: "As simulation 2 with a slight noise transmission: KF and SKF converge and filter "
        "the noise, SSKF does not converge (Fig. 13).",
    }
)
SKF_SIM2_ELEMENTS: Final = (5, 6, 7, 8)
"""SKF Fig. 9 / Fig. 13 plot x5…x8 (1-based, row-major: x_{i+1} is our flat cell i)."""
SKF_SIM1_ELEMENT: Final = 6
"""SKF Fig. 8 plots x6 and its variance P6 for KF and SKF."""
SKF_SIM3_NOISE_AMPLITUDE: Final = 0.2
"""SKF §5.3: uniform measurement noise of maximum amplitude 0.2."""

# --- SKF paper §6: NOx case ------------------------------------------------------------------

NOX_CAL36_SIGMA_W: Final = 7.0
"""SKF (36): the low-gain calibration σw² = 7² for KF and SKF (σv, σf, a, τ as in (34))."""
NOX_UPDATE_WINDOW_S: Final = 400.0
"""SKF §6.2, Fig. 14: maps updated over the first t = 400 s, then used to predict the cycle."""
NOX_FIG16_ELEMENTS: Final = (126, 133)
"""SKF Fig. 16: variances of table elements 126 and 133 (1-based), KF against SKF."""
NOX_CLAIMS: Final = MappingProxyType(
    {
        "fig14": "SKF Fig. 14: with maps updated over 400 s of the SDMP, KF, SKF and SSKF all "
        "predict the NOx sensor signal well.",
        "fig15": "SKF Fig. 15 / (35): the mean absolute prediction error eM(t) of the map "
        "updated until t falls towards the benchmark model's; KF and SKF behave alike and "
        "are faster than SSKF; Cal (36) is slower but less noisy.",
        "fig16": "SKF Fig. 16: KF and SKF variances are 'pretty similar'; an element never "
        "visited grows linearly, visited ones drop while active.",
        "fig17": "SKF Fig. 17: the adaptive map fits the sensor 'in about 30 s'.",
        "fig18": "SKF Fig. 18: on the slower NEDC (poorer excitation) the SKF-updated map "
        "predicts NOx slightly better than the benchmark model.",
    }
)
NOX_FIT_TIME_S: Final = 30.0
"""SKF §6.3, Fig. 17: 'the adaptive map provides a perfect fitting in about 30 s'."""

# --- LPV paper §4 ----------------------------------------------------------------------------

LPV_MEAN_RELATIVE_ERROR: Final = MappingProxyType(
    {
        # LPV §4.1, Fig. 6a: ETC part 1 (our WHTC stands in for the ETC).
        "maf-whtc": 0.1041,
        # LPV §4.2, Fig. 9a: FTP-75 cold-start transient phase.
        "maf-ftp75": 0.0528,
    }
)
LPV_REFS: Final = MappingProxyType(
    {
        "maf-whtc": "LPV §4.1, Figs. 4–6 (ETC part 1)",
        "maf-ftp75": "LPV §4.2, Figs. 7–9 (FTP-75 cold start)",
    }
)
LPV_GRID: Final = "u_δ = 0:4:56 mg/cycle × n_e = 0:250:3000 rpm (LPV §4.1)"

# --- EKF paper Table 1 -----------------------------------------------------------------------

EKF_TABLE1_CLAIM: Final = (
    "EKF §5.2, Table 1: 'all measures, both maximum and mean, are approximately the same for "
    "Aug. and Map. for all system states and the system output, while Def. has significantly "
    "larger errors'; Fig. 5: Map recovers the correction map."
)
EKF_TABLE1_NUMBERS_LOST: Final = (
    "The numbers of Table 1 did not survive the paper's text extraction "
    "(papers/ekf-map-adaptation.txt keeps only its caption), so the pattern is compared."
)

# --- TQ paper Tables III, IV, VI, VII (indices over 5–30 s, TQ (60)–(62)) --------------------

TQ_TABLE_III: Final = MappingProxyType(
    {  # TQ §VI simulation (GT-Power), k = 0.01, λ1 = 150
        "uio": MappingProxyType({"ise": 3.5653e4, "mae": 19.0230, "sd": 2.8135}),
        "smo": MappingProxyType({"ise": 1.3739e5, "mae": 20.4237, "sd": 4.9259}),
        "dirty": MappingProxyType({"ise": 1.0814e5, "mae": 18.9628, "sd": 4.9015}),
    }
)
TQ_TABLE_VI: Final = MappingProxyType(
    {  # TQ §VII engine rig, k = 0.01, λ1 = 350
        "uio": MappingProxyType({"ise": 1.5264e6, "mae": 18.8252, "sd": 2.9120}),
        "smo": MappingProxyType({"ise": 3.4639e6, "mae": 26.5097, "sd": 4.2565}),
        "dirty": MappingProxyType({"ise": 4.2208e6, "mae": 24.8369, "sd": 4.8424}),
    }
)
ADAPTIVE_VARIANTS: Final = (
    ("(50) κ = 0", "adaptive-const", 0.0),
    ("(50) κ = 0.1", "adaptive-const", 0.1),
    ("(54) κ = 0", "adaptive-tv", 0.0),
    ("(54) κ = 0.1", "adaptive-tv", 0.1),
)
"""The four adaptive variants of TQ Tables IV and VII: label, estimator, κ."""
TQ_TABLE_IV: Final = MappingProxyType(
    {  # TQ §VI simulation: k = 0.01, ℓ = 10, Γ = diag(0.1, 100), Θ̂(0) = 0
        "(50) κ = 0": MappingProxyType({"ise": 1.5473e5, "mae": 19.2048, "sd": 2.6222}),
        "(50) κ = 0.1": MappingProxyType({"ise": 1.3263e5, "mae": 14.8248, "sd": 2.4279}),
        "(54) κ = 0": MappingProxyType({"ise": 1.7152e5, "mae": 19.6502, "sd": 2.7607}),
        "(54) κ = 0.1": MappingProxyType({"ise": 7.4863e4, "mae": 12.7438, "sd": 1.8234}),
    }
)
TQ_TABLE_VII: Final = MappingProxyType(
    {  # TQ §VII rig, same parameters
        "(50) κ = 0": MappingProxyType({"ise": 8.6268e5, "mae": 15.4241, "sd": 2.1888}),
        "(50) κ = 0.1": MappingProxyType({"ise": 3.0278e5, "mae": 9.4317, "sd": 1.2967}),
        "(54) κ = 0": MappingProxyType({"ise": 1.0647e6, "mae": 17.2514, "sd": 2.4291}),
        "(54) κ = 0.1": MappingProxyType({"ise": 3.5609e5, "mae": 9.6780, "sd": 1.4044}),
    }
)
TQ_TABLES: Final = MappingProxyType(
    {
        ("torque-si", "observers"): ("Table III", "Figs. 3–4", TQ_TABLE_III),
        ("torque-rig", "observers"): ("Table VI", "Figs. 9–10", TQ_TABLE_VI),
        ("torque-si", "adaptive"): ("Table IV", "Figs. 5–6", TQ_TABLE_IV),
        ("torque-rig", "adaptive"): ("Table VII", "Fig. 11", TQ_TABLE_VII),
    }
)
"""(scenario, family) → (table, figures, values): where each table of ours sits in TQ."""
TQ_WINDOW_S: Final = (5.0, 30.0)
"""TQ §VI: 'calculated using the data point from 5 s to 30 s' (T = 25 s)."""
