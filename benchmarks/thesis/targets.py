"""The dissertation's numbers, read from its Chapters 3-5 ("Nonlinear Black-box Identification of Piezoelectric
Systems", PUC-Rio 2021), with the slips a careful reading finds.

Every value here is copied from the text of the tables and figure captions (no rounding beyond the printed
digits). A :class:`Target` is one row's published figure: ``value`` (the mean, or the single value), ``sd`` when
the dissertation gives a standard deviation, ``n`` the runs behind it, ``low``/``high`` the spread a project value
is judged against (± one published SD, or the range of the published runs, or a tolerance stated in the text),
and ``unit``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Target",
    "TARGETS",
    "SLIPS",
    "TABLE_4_2",
    "TABLE_4_3",
    "TABLE_5_2",
    "TABLE_5_4",
    "TABLE_5_5",
    "TABLE_5_6",
    "FIG_5_13",
    "ARCH",
    "BEST_DS2",
    "target",
]


@dataclass(frozen=True)
class Target:
    """A published figure and the spread a reproduction is judged against (``low`` ≤ value ≤ ``high``)."""

    value: float
    low: float
    high: float
    n: int | None = None
    sd: float | None = None
    unit: str = ""
    source: str = ""
    note: str = ""
    higher_is_better: bool = True
    extra: dict = field(default_factory=dict)


# Table 4.2: layers x neurons -> mean validation FRS R² over the 12 sines, parameters (ReLU, lags 10, 100 epochs)
TABLE_4_2: dict[tuple[int, int], tuple[float, int]] = {
    (3, 25): (0.984742017, 1851),
    (3, 50): (0.992217724, 6201),
    (3, 100): (0.964782331, 22401),
    (4, 25): (0.989210717, 2501),
    (4, 50): (0.916190505, 8751),
    (4, 100): (0.992844673, 32501),
    (5, 25): (0.992375649, 3151),
    (5, 50): (0.986898346, 11301),
    (5, 100): (0.992068821, 42601),
}
# Table 4.3: sine frequency [Hz] -> validation FRS R² of the 4 x 25 network
TABLE_4_3: dict[float, float] = {
    0.1: 0.986797839,
    1.0: 0.989170955,
    10.0: 0.991136621,
    50.0: 0.998469432,
    100.0: 0.998403016,
    150.0: 0.997474415,
    200.0: 0.994559081,
    250.0: 0.985648806,
    300.0: 0.995859260,
    400.0: 0.987992324,
    450.0: 0.997331124,
    500.0: 0.985664909,
}
# Table 5.2 (data set 1, FRS R² on the estimation data): (model, n_u, n_y, n_e, rho_p) -> R²
TABLE_5_2: list[tuple[str, int, int, int | None, float | None, float]] = [
    ("narx", 19, 17, None, None, 0.8830),
    ("narx", 17, 16, None, None, 0.8830),
    ("narx", 18, 18, None, None, 0.8880),
    ("narx", 15, 16, None, None, 0.8920),
    ("armax", 1, 5, 2, None, 0.9000),
    ("armax", 1, 5, 5, None, 0.9010),
    ("armax", 2, 10, 7, None, 0.9040),
    ("armax", 1, 8, 3, None, 0.9040),
    ("armax", 2, 10, 6, None, 0.9060),
    ("narmax", 1, 3, 1, 1e-4, 0.9396),
    ("narmax", 1, 2, 8, 1e-4, 0.9612),
    ("narmax", 1, 2, 3, 1e-4, 0.9629),
    ("narmax", 1, 2, 3, 1e-6, 0.9651),
    ("narmax", 4, 5, 10, 1e-6, 0.9815),
    ("narmax", 4, 4, 1, 1e-6, 0.9819),
    ("narmax", 4, 6, 4, 1e-6, 0.9822),
    ("narmax", 4, 5, 8, 1e-6, 0.9824),
]
# Tables 5.4 / 5.5 (data set 2, 5 runs): (label, ny, hidden, activation) -> (est mean, est SD), (val mean, val SD)
TABLE_5_4_5: list[tuple[str, int, tuple[int, ...], str, tuple[float, float], tuple[float, float]]] = [
    ("256-2-tanh-ny256", 256, (256, 128, 64, 32, 16, 8, 4, 2), "tanh", (0.9244, 0.0292), (0.3841, 0.2378)),
    ("256-2-tanh", 512, (256, 128, 64, 32, 16, 8, 4, 2), "tanh", (0.9628, 0.5274), (0.4204, 0.2444)),
    ("100x3-tanh", 512, (100, 100, 100), "tanh", (0.9890, 0.0043), (0.4341, 0.0750)),
    ("50x5-tanh", 512, (50, 50, 50, 50, 50), "tanh", (0.9950, 0.0014), (0.4383, 0.1122)),
    ("50x2-tanh", 512, (50, 50), "tanh", (0.9951, 0.0025), (0.4950, 0.0953)),
    ("50x2-sigmoid", 512, (50, 50), "sigmoid", (0.9958, 0.0015), (0.4977, 0.2255)),
    ("100x3-sigmoid", 512, (100, 100, 100), "sigmoid", (0.9963, 0.0016), (0.5281, 0.0349)),
    ("75x2-sigmoid", 512, (75, 75), "sigmoid", (0.9964, 0.0015), (0.5642, 0.0705)),
]
#: label -> (n_y, hidden widths, activation) of the eight networks; the best one (Tables 5.6, Fig. 5.13)
ARCH = {lab: (ny, hidden, act) for lab, ny, hidden, act, _, _ in TABLE_5_4_5}
BEST_DS2 = "75x2-sigmoid"
TABLE_5_4 = {lab: est for lab, _, _, _, est, _ in TABLE_5_4_5}
TABLE_5_5 = {lab: val for lab, _, _, _, _, val in TABLE_5_4_5}
# Table 5.6: the five runs of the 75-75 sigmoid network (lags 512): R² OSA/FRS on estimation and validation
TABLE_5_6: dict[str, tuple[float, ...]] = {
    "osa-est": (0.9988, 0.9991, 0.9993, 0.9986, 0.9991),
    "frs-est": (0.9971, 0.9981, 0.9965, 0.9941, 0.9962),
    "osa-val": (0.8805, 0.8930, 0.8973, 0.8924, 0.9065),
    "frs-val": (0.4729, 0.5110, 0.5916, 0.5991, 0.6463),
}
# Figure 5.13 captions: 75 runs of the same network, FRS R² mean and SD
FIG_5_13: dict[str, tuple[float, float, int]] = {
    "est": (0.997181545, 0.001188647, 75),
    "val": (0.54788858, 0.05346327, 75),
}


def _sd_target(mean: float, sd: float, n: int, source: str, note: str = "") -> Target:
    return Target(mean, mean - sd, min(1.0, mean + sd), n=n, sd=sd, source=source, note=note)


def _runs_target(values: tuple[float, ...], source: str) -> Target:
    v = np.asarray(values, dtype=float)
    return Target(
        float(v.mean()),
        float(v.min()),
        float(v.max()),
        n=v.size,
        sd=float(v.std(ddof=1)),
        source=source,
        note="spread: the range of the published runs",
        extra={"runs": list(values)},
    )


def _build() -> dict[str, Target]:
    t: dict[str, Target] = {}
    vals42 = [v for v, _ in TABLE_4_2.values()]
    for (layers, width), (v, n_par) in TABLE_4_2.items():
        # one value per architecture, no SD printed: judged against the spread of the nine architectures
        t[f"table-4.2/{layers}x{width}"] = Target(
            v,
            min(vals42),
            max(vals42),
            n=None,
            source="Table 4.2",
            note="no SD printed; spread: the range of the 9 architectures",
            extra={"parameters": n_par},
        )
    vals43 = list(TABLE_4_3.values())
    for f, v in TABLE_4_3.items():
        t[f"table-4.3/{f:g}hz"] = Target(
            v, min(vals43), max(vals43), n=1, source="Table 4.3", note="one run; spread: the range over the 12 sines"
        )
    for model, nu, ny, ne, rho, v in TABLE_5_2:
        same = [w for m, *_, w in TABLE_5_2 if m == model]
        note = f"one fit; spread: the range of the {model.upper()} rows"
        t[table_5_2_id(model, nu, ny, ne, rho)] = Target(v, min(same), max(same), n=1, source="Table 5.2", note=note)
    for lab, (m, s) in TABLE_5_4.items():
        slip = "spread from the printed SD 0.5274, which cannot be right (see the slips)" if s > 0.5 else ""
        t[f"table-5.4/{lab}"] = _sd_target(m, s, 5, "Table 5.4", slip)
    for lab, (m, s) in TABLE_5_5.items():
        t[f"table-5.5/{lab}"] = _sd_target(m, s, 5, "Table 5.5")
    for key, runs in TABLE_5_6.items():
        t[f"table-5.6/{key}"] = _runs_target(runs, "Table 5.6")
    for key, (m, s, n) in FIG_5_13.items():
        t[f"fig-5.13/{key}"] = _sd_target(m, s, n, "Figure 5.13")
    # §3.1: "The peak around 750 Hz is outside the generated signal frequency band" (read off Figure 3.4)
    t["fig-3.4/peak"] = Target(
        750.0,
        700.0,
        800.0,
        unit="Hz",
        source="§3.1, Figure 3.4",
        higher_is_better=False,
        note="'around 750 Hz' read off a plot; spread: ± 50 Hz",
    )
    # §3.2 / Figure 3.9: "peak in transmitted power at 940kHz with a second peak around 1162kHz"
    t["fig-3.9/peak"] = Target(
        940e3,
        930e3,
        950e3,
        unit="Hz",
        source="§3.2, Figure 3.9",
        higher_is_better=False,
        note="'≈ 940 kHz'; spread: ± 10 kHz",
    )
    t["fig-3.9/second-peak"] = Target(
        1162e3,
        1147e3,
        1177e3,
        unit="Hz",
        source="Figure 3.9",
        higher_is_better=False,
        note="'around 1162 kHz'; spread: ± 15 kHz",
    )
    return t


def table_5_2_id(model: str, nu: int, ny: int, ne: int | None, rho: float | None) -> str:
    """Row id of one Table 5.2 line: ``table-5.2/armax-1-5-2`` (n_u, n_y, n_e), ``narmax-...-rho1e-04``."""
    parts = [model, str(nu), str(ny)] + ([str(ne)] if ne is not None else [])
    rid = "table-5.2/" + "-".join(parts)
    return rid + (f"-rho{rho:.0e}" if rho is not None else "")


TARGETS: dict[str, Target] = _build()


def target(row_id: str) -> Target:
    return TARGETS[row_id]


def _max_sd(mean: float, n: int, top: float = 1.0) -> float:
    """Largest sample SD of ``n`` values ≤ ``top`` with the given mean: n−1 values at ``top``, one below."""
    x = np.full(n, top)
    x[-1] = n * mean - (n - 1) * top
    return float(np.std(x, ddof=1))


def _slips() -> list[str]:
    t43 = float(np.mean(list(TABLE_4_3.values())))
    return [
        f"Table 4.3's twelve values average {t43:.5f}: that is Table 4.2's 5 × 25 row "
        f"({TABLE_4_2[(5, 25)][0]:.5f}), not the 4 × 25 row its caption names ({TABLE_4_2[(4, 25)][0]:.5f}).",
        f"Table 5.4 row 2 prints an SD of 0.5274 beside a mean of 0.9628: five R² values ≤ 1 with that mean have "
        f"an SD of at most {_max_sd(0.9628, 5):.3f} (four runs at 1, one run below), so the printed SD cannot be "
        "the SD of those runs.",
        "§4.1 says the 5 × 25 network gives 'approximately a 3% increase in R²' over the 4 × 25 one; Table 4.2 "
        f"gives {100 * (TABLE_4_2[(5, 25)][0] / TABLE_4_2[(4, 25)][0] - 1):.2f} %.",
    ]


SLIPS: list[str] = _slips()
