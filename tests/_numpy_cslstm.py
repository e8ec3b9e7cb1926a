"""An independent plain-numpy CS-LSTM forward (evaluation mode), from the documented equations.

Works in the reference implementation's own layout and on a PyTorch-layout state_dict:
hist [16, B, 2], nbrs [16, N, 2] (neighbours in grid-id order, lane-major, per sample),
mask [B, 3, 13, 64] bool. Returns fut_pred [25, B, 5] (single-mode) or a list of 6 of them
(lon-major) plus lat_pred [B, 3] and lon_pred [B, 2]. Everything in float64, loops where the
reference has them: it shares no code with diffsense.predictors.
"""

from __future__ import annotations

import numpy as np


def _leaky(x):
    return np.where(x >= 0, x, 0.1 * x)


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def _linear(sd, name, x):
    return x @ sd[f"{name}.weight"].T + sd[f"{name}.bias"]


def _lstm(sd, name, seq):
    """torch.nn.LSTM, one layer, zero initial state; seq [T, N, in] -> all hidden states."""
    w_ih, w_hh = sd[f"{name}.weight_ih_l0"], sd[f"{name}.weight_hh_l0"]
    b_ih, b_hh = sd[f"{name}.bias_ih_l0"], sd[f"{name}.bias_hh_l0"]
    hidden = w_hh.shape[1]
    h = np.zeros((seq.shape[1], hidden))
    c = np.zeros((seq.shape[1], hidden))
    out = []
    for x in seq:
        gates = x @ w_ih.T + b_ih + h @ w_hh.T + b_hh
        i, f, g, o = np.split(gates, 4, axis=-1)
        c = _sigmoid(f) * c + _sigmoid(i) * np.tanh(g)
        h = _sigmoid(o) * np.tanh(c)
        out.append(h)
    return np.stack(out)


def _conv2d(x, w, b):
    """Valid cross-correlation, NCHW input, torch [out, in, kh, kw] kernel."""
    bsz, _, hh, ww = x.shape
    c_out, _, kh, kw = w.shape
    out = np.zeros((bsz, c_out, hh - kh + 1, ww - kw + 1))
    for i in range(hh - kh + 1):
        for j in range(ww - kw + 1):
            patch = x[:, :, i : i + kh, j : j + kw]
            out[:, :, i, j] = np.einsum("bchw,ochw->bo", patch, w) + b
    return out


def _maxpool_2x1_pad1(x):
    """MaxPool2d((2, 1), padding=(1, 0)): pad with -inf, windows of 2 along H, stride 2."""
    bsz, c, hh, ww = x.shape
    padded = np.full((bsz, c, hh + 2, ww), -np.inf)
    padded[:, :, 1:-1] = x
    h_out = (hh + 2 - 2) // 2 + 1
    return np.stack([padded[:, :, 2 * k : 2 * k + 2].max(axis=2) for k in range(h_out)], axis=2)


def _out_act(y):
    return np.concatenate([y[..., :2], np.exp(y[..., 2:4]), np.tanh(y[..., 4:5])], axis=-1)


def _decode(sd, enc):
    seq = np.repeat(enc[None], 25, axis=0)
    return _out_act(_linear(sd, "op", _lstm(sd, "dec_lstm", seq)))


def forward(sd, hist, nbrs, mask):
    """The reference highwayNet.forward in evaluation mode."""
    sd = {k: np.asarray(v, np.float64) for k, v in sd.items()}
    hist, nbrs = np.asarray(hist, np.float64), np.asarray(nbrs, np.float64)
    hist_enc = _lstm(sd, "enc_lstm", _leaky(_linear(sd, "ip_emb", hist)))[-1]
    hist_enc = _leaky(_linear(sd, "dyn_emb", hist_enc))
    nbrs_enc = _lstm(sd, "enc_lstm", _leaky(_linear(sd, "ip_emb", nbrs)))[-1]
    # masked_scatter_: fill the True entries of mask in row-major order from nbrs_enc.
    soc = np.zeros(mask.shape)
    soc[np.asarray(mask, bool)] = nbrs_enc.reshape(-1)
    soc = soc.transpose(0, 3, 2, 1)  # [B, 64, cell, lane]
    soc = _leaky(_conv2d(soc, sd["soc_conv.weight"], sd["soc_conv.bias"]))
    soc = _leaky(_conv2d(soc, sd["conv_3x1.weight"], sd["conv_3x1.bias"]))
    soc = _maxpool_2x1_pad1(soc).reshape(soc.shape[0], -1)
    enc = np.concatenate([soc, hist_enc], axis=1)
    if sd["dec_lstm.weight_ih_l0"].shape[1] == enc.shape[1]:
        return _decode(sd, enc)

    def softmax(z):
        e = np.exp(z - z.max(axis=1, keepdims=True))
        return e / e.sum(axis=1, keepdims=True)

    lat_pred = softmax(_linear(sd, "op_lat", enc))
    lon_pred = softmax(_linear(sd, "op_lon", enc))
    futs = []
    for k in range(2):
        for l in range(3):
            lat = np.zeros((enc.shape[0], 3))
            lon = np.zeros((enc.shape[0], 2))
            lat[:, l] = 1
            lon[:, k] = 1
            futs.append(_decode(sd, np.concatenate([enc, lat, lon], axis=1)))
    return futs, lat_pred, lon_pred
