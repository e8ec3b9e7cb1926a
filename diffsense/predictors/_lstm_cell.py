"""The LSTM cell of CS-LSTM as both differentiation modes compute it.

Gates(x, emb, w_ih, w_hh, b)(x_t, h) gives t = tanh of the halved gate pre-activations
(i/2, f/2, g, o/2): sigmoid(z) = (1 + tanh(z / 2)) / 2, so one tanh over all four gates gives i,
f, g and o once the i, f, o columns of the weights are halved (an exact scaling by a power of
two). `cell_step(t, c, hidden)` is the state update; `unrolled` the plain Python-unrolled forward
pass (straight-line code, no loop carries), the primal of both `_lstm.py` (reverse mode) and
`_lstm_forward.py` (forward mode). `product(a, w)` is every matrix product of the recurrences:
in the weights' precision for its operands (bfloat16 matrices: the "bfloat16" products).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def product(a: jax.Array, w: jax.Array) -> jax.Array:
    """a @ w with the operands in w's precision and the sum in a's: bfloat16 weights (a
    predictor's "bfloat16" products) multiply bfloat16 operands into a float32 sum, which
    XLA:CPU runs at about twice float32's rate on a processor with AVX512-BF16; weights of a's
    own dtype give the plain product."""
    if w.dtype == a.dtype:
        return a @ w
    return jnp.dot(a.astype(w.dtype), w, preferred_element_type=a.dtype)


def halve_ifo(w: jax.Array, hidden: int) -> jax.Array:
    half = jnp.full((hidden,), 0.5, w.dtype)
    return w * jnp.concatenate([half, half, jnp.ones((hidden,), w.dtype), half])


def split_gates(t: jax.Array, hidden: int):
    return tuple(t[..., k * hidden : (k + 1) * hidden] for k in range(4))


def cell_step(t, c, hidden):
    """New (h, c) from t = tanh of the halved gates (i/2, f/2, g, o/2) and the old c."""
    ti, tf, tg, to = split_gates(t, hidden)
    c_new = (0.5 + 0.5 * tf) * c + (0.5 + 0.5 * ti) * tg
    return (0.5 + 0.5 * to) * jnp.tanh(c_new), c_new


def leaky_relu(x: jax.Array) -> jax.Array:
    """LeakyReLU with slope 0.1, the reference's only hidden activation."""
    return jnp.where(x >= 0, x, 0.1 * x)


class Gates:
    """gates(x_t, h) = tanh of the halved pre-activations. `x` is [T, N, d] (a sequence) or [N, in]
    (repeated). A sequence may come with an embedding (emb_w [d, in], emb_b [in]): the LSTM input
    is then leaky_relu(x_t @ emb_w + emb_b), formed inside the step (d = 2 for CS-LSTM's (x, y):
    two multiply-adds, no [T, N, in] array)."""

    def __init__(self, x, emb, w_ih, w_hh, b):
        hidden = w_hh.shape[0]
        self.hidden, self.repeated, self.emb = hidden, x.ndim == 2, emb
        wi, self.wh, bs = (halve_ifo(a, hidden) for a in (w_ih, w_hh, b))
        if self.repeated:
            self.xw = product(x, wi) + bs  # the same input at every step: projected once
        else:
            self.w, self.bs, self.n_in = jnp.concatenate([wi, self.wh], 0), bs, wi.shape[0]

    def pre_embedding(self, xt):
        emb_w, emb_b = self.emb
        return sum(xt[..., k : k + 1] * emb_w[k] for k in range(emb_w.shape[0])) + emb_b

    def input(self, xt):
        return xt if self.emb is None else leaky_relu(self.pre_embedding(xt))

    def __call__(self, xt, h):
        if self.repeated:
            return jnp.tanh(self.xw + product(h, self.wh))
        if h is None:  # h = 0: no recurrent matmul
            return jnp.tanh(product(self.input(xt), self.w[: self.n_in]) + self.bs)
        return jnp.tanh(product(jnp.concatenate([self.input(xt), h], -1), self.w) + self.bs)


def unrolled(steps, x, emb, w_ih, w_hh, b):
    gates = Gates(x, emb, w_ih, w_hh, b)
    h = c = jnp.zeros((x.shape[-2], gates.hidden), x.dtype)  # the state keeps x's precision
    hs = []
    for k in range(steps):
        if gates.repeated:
            t = jnp.tanh(gates.xw) if k == 0 else gates(None, h)
        else:
            t = gates(x[k], h if k else None)
        h, c = cell_step(t, c, gates.hidden)
        hs.append(h)
    return hs
