"""Training of the neural sequence models on simulation error: one home for ``rnn``, ``ss-encoder`` and ``wh-net``.

The models differ only in their networks; how they are fitted is written here once, as deepSI keeps its fitting
loop apart from its models. Two losses, both minimised with Adam (``torch.optim.Adam``), gradient-norm clipping,
an optional cosine step-size schedule (``torch.optim.lr_scheduler.CosineAnnealingLR``; Loshchilov & Hutter 2017,
eq. 5) and early stopping on a held-out free-run RMSE (:class:`BestWeights`):

**Sections with an encoder** (:func:`train_simulation`; Beintema, Tóth & Schoukens, Automatica 2023, eq. (9)–(10)):

    V = 1/(B·T·ny) Σ_sections Σ_{j=0}^{T-1} ‖ y(k_i + j) − ŷ(k_i + j | k_i) ‖²

every section starts at a time k_i with the ``lag`` measured samples before it (from which the network estimates
its initial state) and is simulated T steps on the input alone. An epoch takes either ALL start times of the
estimation records (overlapping, shuffled; the SUBNET loop of ``ss-encoder``) or ``draws`` start times drawn
with replacement (multiple shooting as ``rnn`` trains), in mini-batches of ``batch_size``. Any
``torch.nn.Module`` called as ``model(ypast (B, lag, ny), upast (B, lag, nu), useq (B, T, nu)) -> (B, T, ny)``
fits: :class:`sysid.neural.subnet.SubnetModel` and the recurrent network of :mod:`sysid.neural.rnn` do.

**Records from rest** (:func:`train_records`; the dynoNet fitting of Forgione & Piga 2021): the network maps
``u`` (B, N, n_in) to ``ŷ`` (B, N, n_out) from a zero initial state (:class:`sysid.neural.blocknet.BlockNet`), the
loss skips each record's (or section's) first ``warmup`` samples, where the zero state is a transient.

Data are normalised float pairs ``(u (N, nu), y (N, ny))``; a section never spans two records.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from sysid.neural.cuda_graphs import GraphedRollout, GraphedStep
from sysid.progress import progress

__all__ = [
    "Sections",
    "SimTrainResult",
    "BlockTrainResult",
    "BestWeights",
    "train_simulation",
    "train_records",
    "validation_rmse",
    "adam_step",
]

MAX_RESTARTS = 20  # unstable steps undone (each halving the learning rate) before train_records gives up


class Sections:
    """All sections ``[k - lag, k + T)`` of a list of ``(u, y)`` records, as tensors on ``device``."""

    def __init__(
        self,
        pairs: Sequence[tuple[np.ndarray, np.ndarray]],
        lag: int,
        T: int,
        device: torch.device,
        dtype: torch.dtype = torch.float32,
    ):
        self.lag, self.T = int(lag), int(T)
        us, ys, starts = [], [], []
        offset = 0
        for u, y in pairs:
            n = u.shape[0]
            if n >= self.lag + self.T:
                starts.append(np.arange(self.lag, n - self.T + 1) + offset)
            us.append(u)
            ys.append(y)
            offset += n
        self.starts = np.concatenate(starts) if starts else np.zeros(0, dtype=np.int64)
        self.u = torch.as_tensor(np.concatenate(us), dtype=dtype, device=device)
        self.y = torch.as_tensor(np.concatenate(ys), dtype=dtype, device=device)
        self.device = device
        self._past = torch.arange(-self.lag, 0, device=device)
        self._fut = torch.arange(0, self.T, device=device)

    def __len__(self) -> int:
        return int(self.starts.size)

    def batch(self, k: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(ypast, upast, useq, ytarget) of the sections starting at times ``k`` (indices into the records)."""
        past = k[:, None] + self._past[None, :]
        fut = k[:, None] + self._fut[None, :]
        return self.y[past], self.u[past], self.u[fut], self.y[fut]


@dataclass
class SimTrainResult:
    """What :func:`train_simulation` did: per-epoch training loss (mean section MSE, normalised units), the
    validation RMSE after each epoch (index 0: before training), the epoch whose weights were kept (0 = the
    initial ones), the CPU and wall seconds spent, and whether CUDA graphs replayed the steps."""

    loss_history: list[float] = field(default_factory=list)
    val_history: list[float] = field(default_factory=list)
    best_epoch: int | None = None
    epochs_run: int = 0
    cpu_seconds: float = 0.0
    wall_seconds: float = 0.0
    cuda_graphs: bool = False


@dataclass
class BlockTrainResult(SimTrainResult):
    """What :func:`train_records` did, as :class:`SimTrainResult` says, except that the hold-out RMSE of an epoch
    is that of its forward pass (the weights before that epoch's step); plus why the training stopped and how many
    unstable steps were undone."""

    stopped: str = "epochs"
    restarts: int = 0


def _copy(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of the model's parameters (to step back to, or to keep as the best)."""
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


class BestWeights:
    """Early stopping: the lowest hold-out RMSE seen, the weights and epoch that gave it, and the epochs since."""

    def __init__(self) -> None:
        self.value: float = math.inf
        self.state: dict[str, torch.Tensor] | None = None
        self.epoch: int | None = None
        self.since = 0

    def update(self, value: float, model: torch.nn.Module, epoch: int, force: bool = False) -> None:
        """Keep ``model``'s weights when ``value`` is lower than the best so far (or ``force``)."""
        if force or value < self.value:
            self.value, self.since, self.epoch, self.state = value, 0, epoch, _copy(model)
        else:
            self.since += 1

    def restore(self, model: torch.nn.Module) -> None:
        if self.state is not None:
            model.load_state_dict(self.state)


def _optimiser(
    model: torch.nn.Module, lr: float, epochs: int, lr_min: float | None, graph_device: torch.device | None = None
) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.CosineAnnealingLR | None]:
    """Adam on the trainable parameters and, with ``lr_min``, the cosine schedule from ``lr`` to it over ``epochs``.
    ``graph_device``: a CUDA device whose steps a CUDA graph replays — Adam is then ``capturable`` with its step
    size a tensor there, which the schedule rewrites in place between replays."""
    params = [p for p in model.parameters() if p.requires_grad]
    if graph_device is not None:
        opt = torch.optim.Adam(params, lr=torch.tensor(float(lr), device=graph_device), capturable=True)
    else:
        opt = torch.optim.Adam(params, lr=float(lr))
    sched = (
        torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(int(epochs), 1), eta_min=float(lr_min))
        if lr_min is not None
        else None
    )
    return opt, sched


def adam_step(model: torch.nn.Module, opt: torch.optim.Optimizer, loss: torch.Tensor, clip: float = 0.0) -> None:
    """One optimiser step on ``loss``: clear the gradients, back-propagate, clip their norm (``clip`` > 0), step."""
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if clip:
        torch.nn.utils.clip_grad_norm_(model.parameters(), float(clip))
    opt.step()


@torch.no_grad()
def validation_rmse(
    model: torch.nn.Module,
    pairs: Sequence[tuple[np.ndarray, np.ndarray]],
    lag: int,
    device: torch.device,
    dtype: torch.dtype = torch.float32,
) -> float:
    """Free-run RMSE (normalised units) over validation records, each simulated from its first ``lag``
    samples; ``inf`` when the simulation is non-finite."""
    se, n = 0.0, 0
    for u, y in pairs:
        if u.shape[0] <= lag:
            continue
        ut = torch.as_tensor(u, dtype=dtype, device=device)[None]
        yt = torch.as_tensor(y, dtype=dtype, device=device)[None]
        yh = model(yt[:, :lag], ut[:, :lag], ut[:, lag:])
        d = (yh - yt[:, lag:]).double()
        v = float((d * d).sum().item())
        if not math.isfinite(v):
            return math.inf
        se += v
        n += d.numel()
    return math.sqrt(se / n) if n else math.inf


def train_simulation(
    model: torch.nn.Module,
    train: Sequence[tuple[np.ndarray, np.ndarray]],
    lag: int,
    T: int,
    epochs: int,
    batch_size: int = 256,
    lr: float = 1e-3,
    val: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
    patience: int = 0,
    clip: float = 0.0,
    generator: torch.Generator | None = None,
    device: torch.device = torch.device("cpu"),
    log: Callable[[str], None] | None = None,
    max_seconds: float | None = None,
    lr_min: float | None = None,
    draws: int | None = None,
    dtype: torch.dtype = torch.float32,
    desc: str | None = None,
    cuda_graphs: bool = False,
) -> SimTrainResult:
    """Minimise the truncated T-step simulation loss of ``model`` on ``train`` with Adam (see the module
    docstring); early stopping on the free-run RMSE of ``val`` when given (the best weights are loaded back into
    ``model``). ``patience`` > 0 stops after that many epochs without a better validation RMSE; ``clip`` > 0
    clips the gradient norm; ``max_seconds`` (wall clock) stops after the epoch that passes it — a guard for
    shared machines, not a setting that results should depend on. ``lr_min``: the step size follows a cosine from
    ``lr`` down to ``lr_min`` over ``epochs`` (one step per epoch); ``None`` keeps ``lr`` constant.

    ``draws``: ``None`` — each epoch takes every section once, in an order shuffled by ``generator``; an integer —
    each epoch draws that many section starts with replacement. ``dtype``: the precision of the data (and of the
    model, which the caller has cast). ``desc``: label of the epoch progress bar (``None``: no bar).
    ``cuda_graphs`` (CUDA devices only; the model's forward must not leave the GPU): full batches and the hold-out
    free runs replay CUDA graphs (:mod:`sysid.neural.cuda_graphs`) instead of launching each kernel.
    Returns a :class:`SimTrainResult`; a parameter without gradient (``requires_grad`` off) stays fixed."""
    gen = generator or torch.Generator().manual_seed(0)
    sec = Sections(train, lag, T, device, dtype)
    if len(sec) == 0:
        raise ValueError(f"no record has lag + T = {lag + T} samples for one section")
    graphs = bool(cuda_graphs) and device.type == "cuda"
    opt, sched = _optimiser(model, lr, epochs, lr_min, device if graphs else None)
    res = SimTrainResult(cuda_graphs=graphs)
    c0, w0 = time.process_time(), time.perf_counter()
    best = BestWeights()
    step = GraphedStep(model, opt, sec.batch, int(batch_size), clip) if graphs else None
    rollouts = [GraphedRollout(model, u, y, lag) for u, y in val if u.shape[0] > lag] if graphs and val else None

    def hold_out() -> float:
        if rollouts is None:
            return validation_rmse(model, val or [], lag, device)
        parts = [r.sse() for r in rollouts]
        se, n = sum(p[0] for p in parts), sum(p[1] for p in parts)
        return math.sqrt(se / n) if n and math.isfinite(se) else math.inf

    if val:
        res.val_history.append(hold_out())
        best.update(res.val_history[0], model, 0, force=True)
        res.best_epoch = 0
    starts = torch.as_tensor(sec.starts, device=device)
    epoch_iter = progress(range(1, int(epochs) + 1), desc=desc, unit="epoch", show=desc is not None)
    for ep in epoch_iter:
        if draws is None:
            pick = torch.randperm(len(sec), generator=gen).to(device)
        else:
            pick = torch.randint(0, len(sec), (int(draws),), generator=gen).to(device)
        total = torch.zeros((), dtype=torch.float64, device=device)
        for sel in pick.split(int(batch_size)):
            if step is not None:
                loss = step(starts[sel])
            else:
                ypast, upast, useq, target = sec.batch(starts[sel])
                d = model(ypast, upast, useq) - target
                loss = (d * d).mean()
                adam_step(model, opt, loss, clip)
            total += loss.detach().double() * sel.numel()
        res.loss_history.append(float(total.item()) / pick.numel())
        res.epochs_run = ep
        if sched is not None:
            sched.step()
        msg = f"epoch {ep}: train loss {res.loss_history[-1]:.4g}"
        if val:
            v = hold_out()
            res.val_history.append(v)
            msg += f", validation RMSE {v:.4g}"
            best.update(v, model, ep)
            res.best_epoch = best.epoch
        if log:
            log(msg)
        if not math.isfinite(res.loss_history[-1]) and best.state is not None:
            break  # diverged: the best weights so far are restored below
        if patience and best.since >= int(patience):
            break
        if max_seconds is not None and time.perf_counter() - w0 > float(max_seconds):
            break
    best.restore(model)
    res.cpu_seconds = time.process_time() - c0
    res.wall_seconds = time.perf_counter() - w0
    return res


# ------------------------------------------------------------------------------------------------ from rest
def _masks(
    pairs: Sequence[tuple[np.ndarray, np.ndarray]], warmup: int, val_fraction: float
) -> list[tuple[slice, slice | None]]:
    """(training samples, hold-out samples) of each record: training skips the first ``warmup``; the hold-out is the
    last ``val_fraction`` of the last record."""
    out = []
    for k, (u, _) in enumerate(pairs):
        n = u.shape[0]
        cut = n - int(round(val_fraction * n)) if k == len(pairs) - 1 and val_fraction else n
        out.append((slice(min(warmup, cut), cut), slice(cut, n) if cut < n else None))
    return out


def _full_pass(model: torch.nn.Module, us, ys, masks, n_train: int, n_val: int, backward: bool) -> tuple[float, float]:
    """Simulate every record from rest: (training MSE, hold-out sum of squares); gradients of the training MSE are
    accumulated when ``backward``."""
    sse, vse = 0.0, 0.0
    for u, y, (tr, va) in zip(us, ys, masks):
        with torch.set_grad_enabled(backward):
            yhat = model(u)[0]
            d = yhat[tr] - y[tr]
            part = (d * d).sum() / (n_train * y.shape[1])
        if backward:
            part.backward()
        sse += float(part.item())
        if va is not None:
            dv = (yhat[va] - y[va]).detach()
            vse += float((dv * dv).sum().item())
    return sse, vse


def _window_steps(
    model: torch.nn.Module,
    opt: torch.optim.Optimizer,
    us,
    ys,
    masks,
    window: int,
    batch: int,
    warmup: int,
    n_train: int,
    gen: torch.Generator,
) -> float:
    """One epoch of mini-batch Adam steps on sections of ``window`` samples drawn at random (``gen``) from the
    training parts of the records, each simulated from rest with its first ``warmup`` samples out of the loss;
    as many steps as cover the training samples once on average. Returns the epoch's mean section MSE (inf as soon
    as one step's loss is not finite, before that step is taken)."""
    starts = [(k, tr.start, tr.stop - window) for k, (tr, _) in enumerate(masks) if tr.stop - tr.start >= window]
    steps = max(1, math.ceil(n_train / (batch * (window - warmup))))
    total = 0.0
    for _ in range(steps):
        pick = torch.randint(len(starts), (batch,), generator=gen).tolist()
        offs = torch.rand(batch, generator=gen, dtype=torch.float64).tolist()
        secs = [(starts[p][0], starts[p][1] + int(o * (starts[p][2] - starts[p][1] + 1))) for p, o in zip(pick, offs)]
        u = torch.stack([us[k][0, s : s + window] for k, s in secs])
        y = torch.stack([ys[k][s : s + window] for k, s in secs])
        d = model(u)[:, warmup:] - y[:, warmup:]
        loss = (d * d).mean()
        if not math.isfinite(float(loss.item())):
            return math.inf
        adam_step(model, opt, loss)
        total += float(loss.item())
    return total / steps


def train_records(
    model: torch.nn.Module,
    pairs: Sequence[tuple[np.ndarray, np.ndarray]],
    warmup: int,
    epochs: int,
    lr: float = 1e-3,
    lr_min: float = 1e-5,
    val_fraction: float = 0.0,
    patience: int = 0,
    device: torch.device = torch.device("cpu"),
    log: Callable[[str], None] | None = None,
    log_every: int = 100,
    max_seconds: float | None = None,
    window: int = 0,
    batch: int = 1,
    seed: int = 0,
) -> BlockTrainResult:
    """Adam on the simulation MSE of ``pairs`` (normalised ``(u (N, n_in), y (N, n_out))``) simulated from rest, see
    the module docstring. ``model`` is any float64 module mapping ``u`` (B, N, n_in) to ``ŷ`` (B, N, n_out) from rest
    (a :class:`~sysid.neural.blocknet.BlockNet`, or a single :class:`~sysid.neural.iir.LinearDynamic` layer).

    ``window = 0``: full batch, one step per epoch on the whole records, the hold-out (the last ``val_fraction`` of
    the last record) simulated in the same pass, continuing from the training part, but left out of the loss.
    ``window > warmup``: mini-batches of ``batch`` sections of ``window`` samples (drawn with a generator seeded by
    ``seed``), as many steps per epoch as cover the training samples once; the hold-out is then simulated once per
    epoch after its steps. The step size follows the cosine from ``lr`` to ``lr_min`` over ``epochs``.
    ``best_epoch`` counts the epochs behind the kept weights (0: the initial ones). Without a hold-out the last
    epoch's weights are kept; a non-finite loss restores the last good weights, halves the step size and goes on
    (at most ``MAX_RESTARTS`` times). ``max_seconds`` (wall clock) is a guard for shared machines, not a setting
    results should depend on."""
    us = [torch.as_tensor(u, dtype=torch.float64, device=device)[None] for u, _ in pairs]
    ys = [torch.as_tensor(y, dtype=torch.float64, device=device) for _, y in pairs]
    masks = _masks(pairs, warmup, val_fraction)
    n_train = sum(m.stop - m.start for m, _ in masks)
    n_val = sum(v.stop - v.start for _, v in masks if v is not None)
    if n_train < 1:
        raise ValueError("no training samples after the warm-up and the hold-out")
    window = int(window)
    if window and (window <= warmup or not any(m.stop - m.start >= window for m, _ in masks)):
        raise ValueError(f"window={window} must exceed the warm-up ({warmup}) and fit in a record's training part")
    gen = torch.Generator().manual_seed(int(seed))
    opt, sched = _optimiser(model, lr, epochs, lr_min)
    if sched is None:  # lr_min is a float here: the cosine schedule is always on
        raise ValueError("train_records needs lr_min")
    res = BlockTrainResult()
    c0, w0 = time.process_time(), time.perf_counter()
    best = BestWeights()
    prev_state = _copy(model) if window else None  # sections step before the first check
    for ep in range(1, int(epochs) + 1):
        if window:  # the steps first, then the hold-out of the weights they reached
            sse = _window_steps(model, opt, us, ys, masks, window, int(batch), warmup, n_train, gen)
            vse = (
                math.inf
                if not math.isfinite(sse)
                else (_full_pass(model, us, ys, masks, n_train, n_val, backward=False)[1] if n_val else 0.0)
            )
        else:  # the hold-out of this forward pass: the weights before the step
            opt.zero_grad(set_to_none=True)
            sse, vse = _full_pass(model, us, ys, masks, n_train, n_val, backward=True)
        res.loss_history.append(sse)
        res.epochs_run = ep
        if not (math.isfinite(sse) and math.isfinite(vse)) or sse > 1e6:  # a step left a denominator unstable
            if prev_state is None or res.restarts >= MAX_RESTARTS:
                res.stopped = "non-finite loss"
                break
            model.load_state_dict(prev_state)  # step back and go on at half the step size
            res.restarts += 1
            for grp in opt.param_groups:
                grp["lr"] *= 0.5
            sched.base_lrs = [v * 0.5 for v in sched.base_lrs]
            sched.eta_min *= 0.5
            opt.state.clear()
            continue
        prev_state = _copy(model)  # checked finite: the weights to step back to
        current = math.sqrt(vse / (n_val * ys[-1].shape[1])) if n_val else math.nan
        res.val_history.append(current)
        if n_val:
            best.update(current, model, ep - (0 if window else 1))
            res.best_epoch = best.epoch
        if log and (ep == 1 or ep % int(log_every) == 0):
            log(f"epoch {ep}: train MSE {sse:.4g}, hold-out RMSE {current:.4g}, lr {sched.get_last_lr()[0]:.3g}")
        if patience and n_val and best.since >= int(patience):
            res.stopped = "patience"
            break
        if not window:
            opt.step()
        sched.step()
        if max_seconds is not None and time.perf_counter() - w0 > float(max_seconds):
            res.stopped = "max_seconds"
            break
    best.restore(model)
    if best.state is None and not n_val:
        res.best_epoch = res.epochs_run
    res.cpu_seconds = time.process_time() - c0
    res.wall_seconds = time.perf_counter() - w0
    return res
