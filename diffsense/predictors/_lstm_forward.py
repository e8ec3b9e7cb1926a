"""Forward mode for the CS-LSTM recurrences: the value and its tangent in one pass.

Inside `forward_mode()` (read while tracing) `lstm_last` and `lstm_repeat` are `jax.custom_jvp`
functions, so `jax.jvp` of anything that calls the network works; outside it they keep the
hand-written backward of `_lstm.py` (`jax.custom_vjp`, reverse mode only). JAX cannot give one
function both rules, hence the switch.

Why: with one parameter (the main job's HFOV), d E / d r needs one tangent. Reverse mode costs
a forward pass that keeps or recomputes its gates plus a backward pass; forward mode carries the
tangent rows [du_t, dh] alongside the primal rows [u_t, h] through the same weights, and keeps
nothing for later. `python benchmarks/bench_lstm.py` times both per recurrence and
`python benchmarks/bench_scaling.py` on the whole E(r). Products of fewer than `STACK_ROWS` rows
take primal and tangent rows in one [2N, in + H] @ [in + H, 4H] (a small product runs below the
machine's rate, and twice the rows cost less than twice the time); larger ones, in two.
Both recurrences are `lax.scan`s (unrolled steps, when tried, compiled slower and ran no faster).

The tangent rule: t = tanh(z) gives dt = (1 - t^2) dz on the halved pre-activations, and with
i = (1 + t_i) / 2 (and f, o alike), c' = f c + i g, h' = o tanh(c'):
dc' = dt_f c / 2 + f dc + dt_i g / 2 + i dt_g and dh' = dt_o tanh(c') / 2 + o (1 - tanh(c')^2) dc'.
Tangents of the weights (training's, rarely asked for in forward mode) add [u, h] @ dW + db to
dz and are formed only when given (`symbolic_zeros`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from diffsense.predictors._lstm_cell import (
    Gates,
    halve_ifo,
    leaky_relu,
    product,
    split_gates,
    unrolled,
)

STACK_ROWS = 512  # products of fewer rows than this take primal and tangent rows together
_FORWARD = contextvars.ContextVar("diffsense_lstm_forward_mode", default=False)


@contextlib.contextmanager
def forward_mode():
    """While tracing inside this block, the CS-LSTM is differentiable by `jax.jvp` (forward mode)
    and not by `jax.grad` / `jax.vjp` (reverse mode, the default outside it)."""
    token = _FORWARD.set(True)
    try:
        yield
    finally:
        _FORWARD.reset(token)


def forward_mode_active() -> bool:
    """Whether the recurrences being traced now use the forward-mode rule."""
    return _FORWARD.get()


def _given(t) -> bool:
    return t is not None and not isinstance(t, SymbolicZero)


def _materialise(t, like):
    return t if _given(t) else jnp.zeros_like(like)


def _step_tangent(t, dz, c, dc, hidden):
    """(h', c', dh', dc') of one step from t = tanh(z), the pre-activations' tangent dz and (c, dc)."""
    dt = (1.0 - t * t) * dz
    ti, tf, tg, to = split_gates(t, hidden)
    dti, dtf, dtg, dto = split_gates(dt, hidden)
    c_new = (0.5 + 0.5 * tf) * c + (0.5 + 0.5 * ti) * tg
    dc_new = 0.5 * dtf * c + (0.5 + 0.5 * tf) * dc + 0.5 * dti * tg + (0.5 + 0.5 * ti) * dtg
    tc = jnp.tanh(c_new)
    h_new = (0.5 + 0.5 * to) * tc
    dh_new = 0.5 * dto * tc + (0.5 + 0.5 * to) * (1.0 - tc * tc) * dc_new
    return h_new, c_new, dh_new, dc_new


def _stacked(a, da, w):
    """(a @ w, da @ w): one product of the stacked rows when they are few, else two."""
    if a.shape[0] >= STACK_ROWS:
        return product(a, w), product(da, w)
    n = a.shape[0]
    both = product(jnp.concatenate([a, da], 0), w)
    return both[:n], both[n:]


def _weight_tangents(weights, tangents, hidden):
    """The halved tangents (dw_ih, dw_hh, db) of the weights, or None when none is given."""
    if not any(_given(t) for t in tangents):
        return None
    return tuple(halve_ifo(_materialise(t, w), hidden) for t, w in zip(tangents, weights))


def _repeated_jvp(steps, x, dx, gates, w_ih, dweights, last_only):
    n, hidden = x.shape[0], gates.hidden
    dxw = product(_materialise(dx, x), halve_ifo(w_ih, hidden))
    if dweights is not None:
        dxw = dxw + x @ dweights[0] + dweights[2]

    def step(carry, _):
        h, c, dh, dc = carry
        zh, dzh = _stacked(h, dh, gates.wh)
        z, dz = gates.xw + zh, dxw + dzh
        if dweights is not None:
            dz = dz + h @ dweights[1]
        h, c, dh, dc = _step_tangent(jnp.tanh(z), dz, c, dc, hidden)
        return (h, c, dh, dc), (h, dh)

    zeros = jnp.zeros((n, hidden), x.dtype)
    first = _step_tangent(jnp.tanh(gates.xw), dxw, zeros, zeros, hidden)
    return _loop(step, first, None, steps - 1, last_only)


def _loop(step, first, xs, length, last_only):
    """(hs, dhs) of all steps, or (h, dh) of the last: `first`'s state then a scan of `length`
    more (a scan compiles faster than the unrolled steps and runs as fast: see the module doc)."""
    if last_only:
        last = jax.lax.scan(lambda carry, x: (step(carry, x)[0], None), first, xs, length=length)[0]
        return last[0], last[2]
    _, (hs, dhs) = jax.lax.scan(step, first, xs, length=length)
    return jnp.concatenate([first[0][None], hs]), jnp.concatenate([first[2][None], dhs])


def _input_tangent(gates, xt, dxt, demb):
    """(u_t, du_t): the LSTM input at a step of a sequence and its tangent (`dxt` an array: the
    sequence's tangent is materialised before the scan slices it)."""
    if gates.emb is None:
        return xt, dxt
    pre = gates.pre_embedding(xt)
    emb_w, _ = gates.emb
    dpre = sum(dxt[..., k : k + 1] * emb_w[k] for k in range(emb_w.shape[0]))
    if demb is not None and _given(demb[0]):
        dpre = dpre + sum(xt[..., k : k + 1] * demb[0][k] for k in range(emb_w.shape[0]))
    if demb is not None and _given(demb[1]):
        dpre = dpre + demb[1]
    return leaky_relu(pre), jnp.where(pre >= 0, dpre, 0.1 * dpre)


def _sequence_jvp(x, dx, demb, gates, dweights, last_only):
    n, hidden = x.shape[1], gates.hidden
    dx = _materialise(dx, x)

    def gates_tangent(u, du, h, dh):
        z, dz = _stacked(jnp.concatenate([u, h], -1), jnp.concatenate([du, dh], -1), gates.w)
        if dweights is not None:
            dz = dz + jnp.concatenate([u, h], -1) @ jnp.concatenate(dweights[:2], 0) + dweights[2]
        return z + gates.bs, dz

    def step(carry, xs):
        h, c, dh, dc = carry
        u, du = _input_tangent(gates, *xs, demb)
        z, dz = gates_tangent(u, du, h, dh)
        h, c, dh, dc = _step_tangent(jnp.tanh(z), dz, c, dc, hidden)
        return (h, c, dh, dc), (h, dh)

    u, du = _input_tangent(gates, x[0], dx[0], demb)
    z, dz = _stacked(u, du, gates.w[: gates.n_in])  # h = 0: no recurrent rows
    if dweights is not None:
        dz = dz + u @ dweights[0] + dweights[2]
    zeros = jnp.zeros((n, hidden), x.dtype)
    first = _step_tangent(jnp.tanh(z + gates.bs), dz, zeros, zeros, hidden)
    return _loop(step, first, (x[1:], dx[1:]), x.shape[0] - 1, last_only)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def lstm_forward(steps, last_only, x, emb, w_ih, w_hh, b):
    """The recurrence (`_lstm.py`'s arguments) with the forward-mode rule below."""
    hs = unrolled(steps, x, emb, w_ih, w_hh, b)
    return hs[-1] if last_only else jnp.stack(hs)


@functools.partial(lstm_forward.defjvp, symbolic_zeros=True)
def _lstm_forward_jvp(steps, last_only, primals, tangents):
    x, emb, w_ih, w_hh, b = primals
    dx, demb, dw_ih, dw_hh, db = tangents
    gates = Gates(x, emb, w_ih, w_hh, b)
    dweights = _weight_tangents((w_ih, w_hh, b), (dw_ih, dw_hh, db), gates.hidden)
    if gates.repeated:
        return _repeated_jvp(steps, x, dx, gates, w_ih, dweights, last_only)
    return _sequence_jvp(x, dx, demb, gates, dweights, last_only)
