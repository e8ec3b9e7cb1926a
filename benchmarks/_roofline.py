"""How fast the CS-LSTM could be on this machine: its arithmetic and the machine's matmul rate.

`forward_gflop` counts the multiply-adds (x 2) of one forward pass as diffsense computes it: the
encoder LSTM over the target and its neighbours (16 steps, hidden 64, input 32; the first step
has no recurrent term), the social convolutions (3x3, 64 -> 64 on the 13 x 3 grid, valid; then
3x1, 64 -> 16 on the 11 x 1 result; each as one product of its patches, [B * 11, 3 * 3 * 64] @
[3 * 3 * 64, 64] and [B * 9, 3 * 64] @ [3 * 64, 16], `FullWidthConv`), the dynamics embedding, and the decoder (its constant input projected once, 24
recurrent steps with hidden 128, the 128 -> 5 output at 25 steps). Elementwise work is left out:
it is a few percent and no matmul rate bounds it.

`matmul_rates` times float32 matrix products of the network's own shapes (the encoder step, the
decoder step and the social convolution) and a large square one, in XLA and, when given, in PyTorch, on all cores: the
rate the network's matmuls can reach here. A forward pass cannot run faster than
forward_gflop / the best of those rates.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

ENC_IN, ENC_H, DEC_IN, DEC_H, T_HIST, T_FUT = 32, 64, 112, 128, 16, 25


def forward_gflop(batch: int, neighbours: int, modes: int = 1) -> float:
    """GFLOP of one forward pass for `batch` targets with `neighbours` each, decoding `modes`
    manoeuvres (1: single-mode or the chosen manoeuvre; 6: all)."""
    gates_enc = 4 * ENC_H
    encoder = 2 * gates_enc * (ENC_IN + (T_HIST - 1) * (ENC_IN + ENC_H)) + 2 * T_HIST * 2 * ENC_IN
    social = 2 * 11 * (3 * 3 * 64) * 64 + 2 * 9 * (3 * 64) * 16 + 2 * ENC_H * 32
    dec_in = DEC_IN + (5 if modes > 1 else 0)
    decoder = 2 * 4 * DEC_H * (dec_in + (T_FUT - 1) * DEC_H) + 2 * T_FUT * DEC_H * 5
    per_target = (neighbours + 1) * encoder + social + modes * decoder
    return batch * per_target / 1e9


def _best_time(fn, repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def matmul_shapes(batch: int, neighbours: int) -> dict[str, tuple[int, int, int]]:
    """(m, k, n) of the network's two recurrent matmuls, its social convolution and a large square
    product."""
    return {"encoder step": (batch * (neighbours + 1), ENC_IN + ENC_H, 4 * ENC_H),
            "decoder step": (batch, DEC_H, 4 * DEC_H), "social conv": (batch * 11, 3 * 3 * 64, 64),
            "2048 square": (2048, 2048, 2048)}


def matmul_rates(batch: int, neighbours: int, repeats: int = 30, torch=None) -> dict[str, dict[str, float]]:
    """{shape name: {"xla": GFLOP/s, "xla_bf16": GFLOP/s, "torch": GFLOP/s}} (best of `repeats`;
    xla_bf16 the same product on bfloat16 operands into a float32 sum; torch only if given)."""
    rng = np.random.default_rng(0)
    out = {}
    for name, (m, k, n) in matmul_shapes(batch, neighbours).items():
        a, b = rng.random((m, k), np.float32), rng.random((k, n), np.float32)
        ja, jb = jnp.asarray(a), jnp.asarray(b)
        product = jax.jit(jnp.matmul).lower(ja, jb).compile()
        gflop = 2 * m * k * n / 1e9
        out[name] = {"xla": gflop / _best_time(lambda: product(ja, jb).block_until_ready(), repeats)}
        ha, hb = ja.astype(jnp.bfloat16), jb.astype(jnp.bfloat16)
        half = jax.jit(lambda x, y: jnp.dot(x, y, preferred_element_type=jnp.float32)).lower(ha, hb).compile()
        out[name]["xla_bf16"] = gflop / _best_time(lambda: half(ha, hb).block_until_ready(), repeats)
        if torch is not None:
            ta, tb = torch.from_numpy(a), torch.from_numpy(b)
            with torch.no_grad():
                out[name]["torch"] = gflop / _best_time(lambda: ta @ tb, repeats)
    return out
