"""Twin configuration plumbing (twins.base) on a tiny first-order twin defined here."""

import dataclasses

import numpy as np
import pytest

from sysid.errors import ConfigError
from twins.base import EffectSpec, Twin, param_info, pfield


@dataclasses.dataclass
class _P:
    gain: float = pfield(2.0, "um/V", 0.0, 10.0, "static gain")
    tau_s: float = pfield(0.01, "s", 1e-4, 1.0, "time constant")
    offset_um: float = pfield(0.0, "um", -5.0, 5.0, "drift offset")
    fluid: str = pfield("water", "", doc="medium", choices=("water", "oil"))


class _Toy(Twin):
    """first-order toy twin"""

    name = "toy"
    Params = _P
    EFFECTS = {
        "offset": EffectSpec("offset", "toy", "constant offset", "residual mean ≠ 0", {"value": "offset_um"}),
        "lag": EffectSpec("lag", "toy", "first-order lag", "phase lag", {"tau": "tau_s"}, default_on=True),
    }
    CALIBRATION_PARAMS = ("gain", "tau_s")

    def simulate(self, u, fs):
        a = np.exp(-1 / (fs * self.params.tau_s)) if self.has("lag") else 0.0
        y = np.empty_like(u)
        s = 0.0
        for k, v in enumerate(u):
            s = a * s + (1 - a) * self.params.gain * v
            y[k] = s
        return y + (self.params.offset_um if self.has("offset") else 0.0)

    def generate(self, protocol, **kw):
        raise NotImplementedError


def test_options_order_and_types():
    tw = _Toy.from_options(set_=["gain=3,fluid=oil"], effect=["offset:value=1.5"], without=["lag"])
    assert tw.params.gain == 3.0 and tw.params.fluid == "oil" and tw.params.offset_um == 1.5
    assert tw.effects == {"offset"}
    assert _Toy.from_options(effects="none").effects == frozenset()


@pytest.mark.parametrize(
    "kw,needle",
    [
        (dict(set_=["nope=1"]), "valid: gain"),
        (dict(set_=["gain=99"]), "out of range"),
        (dict(set_=["fluid=honey"]), "not one of"),
        (dict(effect=["bogus"]), "valid: offset, lag"),
        (dict(effect=["offset:zzz=1"]), "valid: value"),
        (dict(set_=["gain=abc"]), "expected float"),
    ],
)
def test_bad_options_refused_with_valid_list(kw, needle):
    with pytest.raises(ConfigError, match=needle):
        _Toy.from_options(**kw)


def test_params_file_round_trip_and_calibration(tmp_path):
    from sysid.data.record import Record

    fs = 1000.0
    u = np.sign(np.sin(2 * np.pi * 5 * np.arange(2000) / fs))
    truth = _Toy.from_options(set_=["gain=4.2,tau_s=0.02"])
    rec = Record(u=u, y=truth.simulate(u, fs), fs=fs)
    res = _Toy().calibrate(rec)
    assert res.fitted["gain"] == pytest.approx(4.2, rel=1e-6)
    assert res.fitted["tau_s"] == pytest.approx(0.02, rel=1e-5)
    assert res.scores["estimation"]["r2"] > 0.999999
    path = res.twin.save_params(tmp_path / "p.json")
    again = _Toy.from_options(params_file=path)
    assert again.params == res.twin.params and again.effects == res.twin.effects


def test_parameter_bounds_for_the_searches():
    """The searches over a parameter read its documented range as floats; a parameter without one is refused."""

    @dataclasses.dataclass(frozen=True)
    class P:
        gain: float = pfield(2.0, "V/V", 1, 10, "gain")
        offset: float = pfield(0.0, "V", doc="no documented range")

    info = param_info(P)
    assert info["gain"].bounds() == (1.0, 10.0) and all(type(v) is float for v in info["gain"].bounds())
    with pytest.raises(ConfigError, match=r"^parameter offset has no documented range \[lo, hi\]$"):
        info["offset"].bounds()
