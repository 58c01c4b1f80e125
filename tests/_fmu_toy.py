"""A small twin for the FMU exporter tests: first-order lag, a hysteresis-free static gain, a list and a
string parameter, and seeded measurement noise drawn per sample exactly as the stepper draws it."""

import dataclasses

import numpy as np

from twins.base import EffectSpec, Twin, pfield


@dataclasses.dataclass
class ToyParams:
    gain: float = pfield(2.0, "um/V", 0.0, 10.0, "static gain")
    tau_s: float = pfield(0.01, "s", 1e-4, 1.0, "time constant")
    offset_um: float = pfield(0.0, "um", -5.0, 5.0, "drift offset")
    order: int = pfield(1, "", 1, 3, "number of cascaded lags")
    weights: list = pfield([1.0, 0.5], "", doc="output weights of the first two stages")
    fluid: str = pfield("water", "", doc="medium (scales the gain)", choices=("water", "oil"))
    noise_um: float = pfield(0.01, "um", 0.0, 1.0, "measurement noise RMS")


class ToyTwin(Twin):
    """Cascade of first-order lags with noise (FMU exporter test twin)."""

    name = "toy"
    Params = ToyParams
    units = {"u": "V", "y": "um"}
    EFFECTS = {
        "offset": EffectSpec("offset", "toy", "constant offset", "residual mean != 0", {"value": "offset_um"}),
        "lag": EffectSpec("lag", "toy", "first-order lag", "phase lag", {"tau": "tau_s"}, default_on=True),
        "measurement_noise": EffectSpec("measurement_noise", "toy", "sensor noise", "white residual",
                                        {"rms": "noise_um"}, default_on=True),
    }

    def make_stepper(self, fs):
        return _ToyStepper(self, fs)

    def simulate(self, u, fs):
        st = self.make_stepper(fs)
        st.reset()
        y = np.array([st.step(float(v)) for v in u])
        return y

    def generate(self, protocol, **kw):
        raise NotImplementedError


class _ToyStepper:
    def __init__(self, twin, fs):
        p = twin.params
        self.a = float(np.exp(-1 / (fs * p.tau_s))) if twin.has("lag") else 0.0
        self.k = p.gain * (1.0 if p.fluid == "water" else 0.8)
        self.order = p.order
        self.w = list(p.weights) + [0.0] * 3
        self.off = p.offset_um if twin.has("offset") else 0.0
        self.noise = p.noise_um if twin.has("measurement_noise") else 0.0
        self.seed = twin.seed

    def reset(self):
        self.s = [0.0] * self.order
        self.rng = np.random.default_rng(self.seed)

    def step(self, u):
        x = self.k * u
        out = 0.0
        for i in range(self.order):
            self.s[i] = self.a * self.s[i] + (1 - self.a) * x
            x = self.s[i]
            out += self.w[i] * x if i < 2 else x
        if self.noise:
            out += self.noise * self.rng.standard_normal()
        return out + self.off
