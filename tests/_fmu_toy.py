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
        "measurement_noise": EffectSpec(
            "measurement_noise", "toy", "sensor noise", "white residual", {"rms": "noise_um"}, default_on=True
        ),
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


@dataclasses.dataclass
class EchoParams:
    delay_s: float = pfield(20e-6, "s", 1e-6, 1e-4, "time of flight")
    f0_hz: float = pfield(1e6, "Hz", 1e5, 5e6, "transducer resonance")
    q: float = pfield(5.0, "", 1.0, 50.0, "transducer quality factor")
    echo_gain: float = pfield(0.2, "", 0.0, 1.0, "triple-transit echo amplitude")
    gain: float = pfield(1e-2, "", 0.0, 1.0, "passband gain of the channel")
    sat_v: float = pfield(100.0, "V", 1.0, 1000.0, "amplifier saturation voltage")
    amp_gain: float = pfield(30.0, "", 1.0, 1000.0, "amplifier small-signal voltage gain")
    noise_v: float = pfield(1e-4, "V", 0.0, 1.0, "receiver noise RMS")
    crosstalk: float = pfield(1e-3, "", 0.0, 1.0, "gain of the undelayed electrical path (band-pass)")


class EchoTwin(Twin):
    """Delay + resonant band-pass + triple-transit echo, FFT-simulated like the acoustic twin."""

    name = "echo"
    Params = EchoParams
    units = {"u": "V", "y": "V"}
    EFFECTS = {
        "echo": EffectSpec(
            "echo", "echo", "triple-transit echo", "repeat at 3 ToF", {"gain": "echo_gain"}, default_on=True
        ),
        "measurement_noise": EffectSpec(
            "measurement_noise", "echo", "receiver noise", "white", {"rms": "noise_v"}, default_on=True
        ),
        "crosstalk": EffectSpec(
            "crosstalk", "echo", "electrical path without delay", "lag-0 correlation", {"c": "crosstalk"}
        ),
    }
    default_fs = 100e6

    def make_stepper(self, fs):
        raise NotImplementedError("FFT-based twin")

    def frequency_response(self, f_hz):
        p = self.params
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        w0 = 2 * np.pi * p.f0_hz
        g = (s * w0 / p.q) / (s * s + s * w0 / p.q + w0 * w0)
        H = p.gain * g * g * np.exp(-s * p.delay_s)
        if self.has("echo"):
            H = H * (1 + p.echo_gain * np.exp(-2 * s * p.delay_s))
        if self.has("crosstalk"):
            H = H + p.crosstalk * (1 - np.exp(-s * 2e-7))  # two spikes 200 ns apart, no flight time
        return H

    def amplifier(self, x):
        p = self.params
        return p.sat_v * np.tanh(p.amp_gain * np.asarray(x, dtype=float) / p.sat_v)

    def measure(self, y, fs, rng):
        y = np.asarray(y, dtype=float)
        if self.has("measurement_noise"):
            y = y + self.params.noise_v * rng.standard_normal(y.shape)
        return y

    def simulate(self, u, fs):
        u = np.asarray(u, dtype=float)
        x = self.amplifier(u)
        n = len(u)
        nfft = 1 << int(
            np.ceil(np.log2(n + 4 * self.params.delay_s * fs + 20 * self.params.q * fs / self.params.f0_hz))
        )
        H = self.frequency_response(np.fft.rfftfreq(nfft, 1 / fs))
        y = np.fft.irfft(np.fft.rfft(x, nfft) * H, nfft)[:n]
        return self.measure(y, fs, np.random.default_rng(self.seed))

    def generate(self, protocol, **kw):
        raise NotImplementedError
