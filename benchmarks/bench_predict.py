"""Benchmark: CS-LSTM forward and input-gradient time, JAX (this project) vs the PyTorch reference.

    python benchmarks/bench_predict.py [--batch 128] [--neighbours 12] [--repeats 20] [--checkpoint PATH]

B targets with N neighbours each (distinct random grid slots), float32, CPU. JAX runs the compact
path (`predict_mean`: only the N neighbours are encoded) under plain jax.jit; "gradient" is
d(sum of predicted means)/d(target and neighbour histories, occupancy weights). The PyTorch side
is a re-implementation of the reference highwayNet.forward in evaluation mode (masked_scatter_
into the grid, one decode per manoeuvre), with the same weights; its gradient is w.r.t. the
histories. "forward" is the predicted mean (manoeuvre variant: the most probable manoeuvre,
decoded alone); "all modes" decodes all 6 manoeuvres like the reference's forward (the torch
column is the same call in both rows). Times are medians over --repeats interleaved calls after
warm-up; compile time is reported apart.
torch is optional (never a runtime dependency): without it only the JAX rows are printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.predictors import (
    CSLSTMPredictor,
    load_predictor,
    predict_mean,
    predict_model_frame,
    si_to_model,
    state_dict_from_model,
)
from diffsense.predictors._model import new_model


def _inputs(b: int, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    hist = np.stack([25 * 0.2 * np.arange(-15, 1)[None].repeat(b, 0), rng.normal(0, 0.3, (b, 16))], -1)
    nbr_hist = hist[:, None] + rng.normal(0, 10, (b, n, 1, 2))
    slot = np.stack([rng.choice([s for s in range(39) if s != 19], n, replace=False) for _ in range(b)])
    weight = np.ones((b, n))
    return hist.astype(np.float32), nbr_hist.astype(np.float32), slot.astype(np.int32), weight.astype(np.float32)


def _time_interleaved(fns: dict, repeats: int) -> dict[str, float]:
    """Median seconds per call of each function, calls interleaved so that all of them see the
    same background load (the machine is shared)."""
    for fn in fns.values():
        fn()  # warm-up
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(t) for name, t in times.items()}


def _jax_fns(predictor: CSLSTMPredictor, args):
    forward = jax.jit(predict_mean)

    def loss(hist, nbr_hist, weight, p, slot):
        return jnp.sum(predict_mean(p, hist, nbr_hist, slot, weight))

    grad = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))
    hist, nbr_hist, slot, weight = (jnp.asarray(a) for a in args)
    t0 = time.perf_counter()
    forward.lower(predictor, hist, nbr_hist, slot, weight).compile()
    compile_fwd = time.perf_counter() - t0
    t0 = time.perf_counter()
    grad.lower(hist, nbr_hist, weight, predictor, slot).compile()
    compile_grad = time.perf_counter() - t0
    all_modes = jax.jit(lambda p, *a: predict_model_frame(p, *(si_to_model(x) for x in a[:2]), *a[2:]).fut)
    fns = {
        "forward": lambda: forward(predictor, hist, nbr_hist, slot, weight).block_until_ready(),
        "forward_all_modes": lambda: all_modes(predictor, hist, nbr_hist, slot, weight).block_until_ready(),
        "gradient": lambda: jax.block_until_ready(grad(hist, nbr_hist, weight, predictor, slot)),
    }
    return fns, {"compile_forward": compile_fwd, "compile_gradient": compile_grad}


def _torch_model(sd: dict[str, np.ndarray]):
    """The reference highwayNet (evaluation mode), with weights from a state_dict."""
    import torch
    from torch import nn

    maneuvers = sd["dec_lstm.weight_ih_l0"].shape[1] == 117

    class HighwayNet(nn.Module):
        def __init__(self):
            super().__init__()
            self.ip_emb = nn.Linear(2, 32)
            self.enc_lstm = nn.LSTM(32, 64, 1)
            self.dyn_emb = nn.Linear(64, 32)
            self.soc_conv = nn.Conv2d(64, 64, 3)
            self.conv_3x1 = nn.Conv2d(64, 16, (3, 1))
            self.soc_maxpool = nn.MaxPool2d((2, 1), padding=(1, 0))
            self.dec_lstm = nn.LSTM(112 + (5 if maneuvers else 0), 128)
            self.op = nn.Linear(128, 5)
            self.op_lat = nn.Linear(112, 3)
            self.op_lon = nn.Linear(112, 2)
            self.leaky_relu = nn.LeakyReLU(0.1)
            self.softmax = nn.Softmax(dim=1)

        def forward(self, hist, nbrs, masks):
            _, (hist_enc, _) = self.enc_lstm(self.leaky_relu(self.ip_emb(hist)))
            hist_enc = self.leaky_relu(self.dyn_emb(hist_enc.view(hist_enc.shape[1], hist_enc.shape[2])))
            _, (nbrs_enc, _) = self.enc_lstm(self.leaky_relu(self.ip_emb(nbrs)))
            nbrs_enc = nbrs_enc.view(nbrs_enc.shape[1], nbrs_enc.shape[2])
            soc_enc = torch.zeros_like(masks).float()
            soc_enc = soc_enc.masked_scatter_(masks, nbrs_enc)
            soc_enc = soc_enc.permute(0, 3, 2, 1)
            soc_enc = self.soc_maxpool(self.leaky_relu(self.conv_3x1(self.leaky_relu(self.soc_conv(soc_enc)))))
            soc_enc = soc_enc.view(-1, 80)
            enc = torch.cat((soc_enc, hist_enc), 1)
            if not maneuvers:
                return self.decode(enc)
            lat_pred = self.softmax(self.op_lat(enc))
            lon_pred = self.softmax(self.op_lon(enc))
            fut_pred = []
            for k in range(2):
                for l in range(3):
                    lat = torch.zeros(enc.shape[0], 3)
                    lon = torch.zeros(enc.shape[0], 2)
                    lat[:, l] = 1
                    lon[:, k] = 1
                    fut_pred.append(self.decode(torch.cat((enc, lat, lon), 1)))
            return fut_pred, lat_pred, lon_pred

        def decode(self, enc):
            enc = enc.repeat(25, 1, 1)
            h_dec, _ = self.dec_lstm(enc)
            fut = self.op(h_dec)
            return torch.cat([fut[..., :2], torch.exp(fut[..., 2:4]), torch.tanh(fut[..., 4:5])], -1)

    net = HighwayNet()
    net.load_state_dict({k: torch.from_numpy(np.array(v, np.float32)) for k, v in sd.items()})
    net.eval()
    return net


def _torch_fns(sd, args, reference_mean: np.ndarray):
    import torch

    from diffsense.predictors import si_to_model

    hist_m, nbr_m, slot, _ = args
    b, n = slot.shape
    order = np.argsort(slot, axis=1, kind="stable")  # the reference wants grid-id order per sample
    slot_sorted = np.take_along_axis(slot, order, 1)
    nbr_sorted = np.take_along_axis(nbr_m, order[..., None, None], 1)
    hist = torch.from_numpy(np.asarray(si_to_model(hist_m), np.float32).transpose(1, 0, 2).copy())
    nbrs = torch.from_numpy(np.asarray(si_to_model(nbr_sorted), np.float32).reshape(b * n, 16, 2).transpose(1, 0, 2).copy())
    mask = np.zeros((b, 39, 64), bool)
    mask[np.arange(b)[:, None], slot_sorted] = True
    mask = torch.from_numpy(mask.reshape(b, 3, 13, 64))
    net = _torch_model(sd)
    maneuvers = sd["dec_lstm.weight_ih_l0"].shape[1] == 117

    def mean_of(out):
        if not maneuvers:
            return out[..., :2]
        futs, lat, lon = out
        idx = lon.argmax(1) * 3 + lat.argmax(1)
        return torch.stack(futs)[idx, :, torch.arange(b)].transpose(0, 1)[..., :2]

    with torch.no_grad():
        mu = mean_of(net(hist, nbrs, mask)).numpy().transpose(1, 0, 2)  # [B, 25, 2] model frame
    from diffsense.predictors import model_to_si

    agree = float(np.max(np.abs(np.asarray(model_to_si(mu)) - reference_mean)))

    def forward():
        with torch.no_grad():
            net(hist, nbrs, mask)

    def gradient():
        h = hist.clone().requires_grad_(True)
        nb = nbrs.clone().requires_grad_(True)
        mean_of(net(h, nb, mask)).sum().backward()

    return {"forward": forward, "forward_all_modes": forward, "gradient": gradient}, agree


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=128)
    parser.add_argument("--neighbours", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--checkpoint", default=None, help="weights to use (default: random init of both variants)")
    args = parser.parse_args()
    inputs = _inputs(args.batch, args.neighbours)
    try:
        import torch

        torch_version = torch.__version__
    except ImportError:
        torch_version = None
    if args.checkpoint:
        predictors = [load_predictor(args.checkpoint)]
    else:
        predictors = [CSLSTMPredictor.from_model(new_model(m, seed=0)) for m in (False, True)]
    print(f"CS-LSTM, B = {args.batch}, {args.neighbours} neighbours per target, float32, CPU "
          f"({os.cpu_count()} cores), median of {args.repeats}; jax {jax.__version__}, torch {torch_version}"
          + (f" ({torch.get_num_threads()} threads)" if torch_version else ""))
    print(f"{'variant':<10} {'op':<9} {'jax [ms]':>9} {'torch [ms]':>11} {'speed-up':>9} {'jax compile [s]':>16}")
    for predictor in predictors:
        name = "manoeuvre" if predictor.maneuvers else "single"
        fns, compile_s = _jax_fns(predictor, inputs)
        fns = {f"jax_{k}": v for k, v in fns.items()}
        agree = None
        if torch_version is not None:
            ref = np.asarray(jax.jit(predict_mean)(predictor, *inputs))
            tfns, agree = _torch_fns(state_dict_from_model(predictor.model()), inputs, ref)
            fns |= {f"torch_{k}": v for k, v in tfns.items()}
        t = _time_interleaved(fns, args.repeats)
        ops = ("forward", "forward_all_modes", "gradient") if predictor.maneuvers else ("forward", "gradient")
        compile_s["compile_forward_all_modes"] = float("nan")
        for op in ops:
            tr = t.get(f"torch_{op}")
            t_torch = f"{1e3 * tr:11.1f}" if tr else f"{'-':>11}"
            speedup = f"{tr / t[f'jax_{op}']:8.1f}x" if tr else f"{'-':>9}"
            c = compile_s["compile_" + op]
            compile_txt = f"{c:16.1f}" if c == c else f"{'-':>16}"  # not measured for all modes
            print(f"{name:<10} {op.replace('forward_all_modes', 'all modes'):<9} {1e3 * t[f'jax_{op}']:9.1f} {t_torch} {speedup} {compile_txt}")
        if agree is not None:
            print(f"{'':<10} (torch vs jax predicted mean: max |diff| = {agree:.2e} m)")


if __name__ == "__main__":
    main()
