"""The one training loop of the sequence models (sysid.neural.training) against its definition: Adam on the mean
squared T-step simulation error of sections [k - lag, k + T) of the records, the sections of an epoch either all
start times in a shuffled order or start times drawn with replacement. The reference below is written out from
that definition with plain numpy slicing and torch.optim.Adam; the loop must give the same weights to the bit,
with the SUBNET network of ss-encoder and the recurrent network of rnn alike, and the rnn identifier must train
through it."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.data.record import Record  # noqa: E402
from sysid.neural.rnn import RNNStateSpace, _Net  # noqa: E402
from sysid.neural.subnet import SubnetModel  # noqa: E402
from sysid.neural.training import train_simulation  # noqa: E402

LAG, T, BATCH, EPOCHS = 4, 6, 16, 2


def _pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(0)
    out = []
    for n in (60, 45, 8):  # the last record is too short for a section and must be skipped
        u = rng.standard_normal((n, 1))
        y = np.convolve(u[:, 0], [0.0, 0.5, 0.25], mode="full")[:n, None] + 0.01 * rng.standard_normal((n, 1))
        out.append((u, y))
    return out


def _reference(model: torch.nn.Module, pairs, draws: int | None, seed: int, clip: float = 0.0) -> None:
    """Adam on V = mean over a batch of sections of (y − ŷ)², sections listed record by record, start by start."""
    secs = [(u, y, k) for u, y in pairs for k in range(LAG, u.shape[0] - T + 1)]
    gen = torch.Generator().manual_seed(seed)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    for _ in range(EPOCHS):
        order = (
            torch.randperm(len(secs), generator=gen)
            if draws is None
            else torch.randint(0, len(secs), (draws,), generator=gen)
        ).tolist()
        for a in range(0, len(order), BATCH):
            chosen = [secs[i] for i in order[a : a + BATCH]]
            ypast = torch.as_tensor(np.stack([y[k - LAG : k] for u, y, k in chosen]), dtype=torch.float32)
            upast = torch.as_tensor(np.stack([u[k - LAG : k] for u, y, k in chosen]), dtype=torch.float32)
            useq = torch.as_tensor(np.stack([u[k : k + T] for u, y, k in chosen]), dtype=torch.float32)
            target = torch.as_tensor(np.stack([y[k : k + T] for u, y, k in chosen]), dtype=torch.float32)
            d = model(ypast, upast, useq) - target
            loss = (d * d).mean()
            opt.zero_grad()
            loss.backward()
            if clip:
                torch.nn.utils.clip_grad_norm_(model.parameters(), clip)
            opt.step()


def _networks():
    torch.manual_seed(1)
    yield "subnet", SubnetModel(2, 1, 1, LAG, LAG, (8,), (8,), (8,))
    torch.manual_seed(1)
    yield "rnn", _Net(2 * LAG, [8], 3, 1, 1, "gru", n_enc=LAG)


@pytest.mark.parametrize("draws", [None, 11])
@pytest.mark.parametrize("which", ["subnet", "rnn"])
def test_the_shared_loop_is_adam_on_the_section_simulation_error(which, draws):
    net = dict(_networks())[which]
    ref = copy.deepcopy(net)
    pairs = _pairs()
    train_simulation(
        net, pairs, LAG, T, EPOCHS, BATCH, lr=1e-2, clip=0.5, draws=draws, generator=torch.Generator().manual_seed(3)
    )
    _reference(ref, pairs, draws, seed=3, clip=0.5)
    got, want = net.state_dict(), ref.state_dict()
    assert all(torch.equal(got[k], want[k]) for k in want)
    assert any(not torch.equal(got[k], v) for k, v in dict(_networks())[which].state_dict().items())  # it trained


def test_rnn_reads_the_input_only_up_to_the_sample_before_each_output():
    """ŷ(t) = readout(h(t)) with h(t) = GRU(u(t−1), h(t−1)): changing u(t0+T−1), the last input of a section,
    changes no output, and changing u(t0) changes ŷ(t0+1) but not ŷ(t0)."""
    torch.manual_seed(0)
    net = _Net(2 * LAG, [8], 3, 1, 1, "gru", n_enc=LAG).double()
    g = torch.Generator().manual_seed(0)
    ypast, upast = (
        torch.randn(2, LAG, 1, generator=g, dtype=torch.float64),
        torch.randn(2, LAG, 1, generator=g, dtype=torch.float64),
    )
    useq = torch.randn(2, T, 1, generator=g, dtype=torch.float64)
    base = net(ypast, upast, useq)
    last, first = useq.clone(), useq.clone()
    last[:, -1] += 1.0
    first[:, 0] += 1.0
    assert torch.equal(net(ypast, upast, last), base)
    moved = net(ypast, upast, first)
    assert torch.equal(moved[:, 0], base[:, 0]) and not torch.equal(moved[:, 1], base[:, 1])


def test_the_rnn_identifier_trains_through_the_shared_loop():
    """RNNStateSpace.fit = its network, seeded, trained by train_simulation with ceil(rows / window) draws."""
    pairs = _pairs()
    recs = [Record(u=u[:, 0], y=y[:, 0], fs=1.0) for u, y in pairs[:2]]
    m = RNNStateSpace(
        n_state=3, n_enc=LAG, enc_hidden=[8], window=T, batch_size=BATCH, epochs=EPOCHS, lr=1e-2, seed=5, device="cpu"
    ).fit(recs)
    norm = m.normaliser_
    scaled = [(norm.transform_u(r.u)[:, None], norm.transform_y(r.y)[:, None]) for r in recs]
    torch.manual_seed(5)
    net = m._build(1, 1)
    rows = sum(u.shape[0] - LAG for u, _ in scaled)
    train_simulation(
        net,
        scaled,
        LAG,
        T,
        EPOCHS,
        BATCH,
        lr=1e-2,
        clip=1.0,
        draws=math.ceil(rows / T),
        generator=torch.Generator().manual_seed(5),
    )
    assert all(np.array_equal(v.detach().double().numpy(), m.state_dict_[k]) for k, v in net.state_dict().items())
