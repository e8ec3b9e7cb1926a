"""The PyTorch reference CS-LSTM (highwayNet, evaluation mode) for benchmarks/bench_predict.py.

A re-implementation of the reference forward with its own layout: time-major histories, the
neighbours of all samples stacked in grid-id order, and a [B, 3, 13, 64] boolean mask that
`masked_scatter_` fills. Needs torch (the `bench` extra); imported only by the benchmark.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from diffsense.predictors import model_to_si, si_to_model


class HighwayNet(nn.Module):
    """The reference network; `maneuvers` selects the manoeuvre-based decoder."""

    def __init__(self, maneuvers: bool):
        super().__init__()
        self.maneuvers = maneuvers
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
        if not self.maneuvers:
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


def reference_net(sd: dict[str, np.ndarray]) -> HighwayNet:
    """The network in evaluation mode with weights from a PyTorch-layout state_dict, frozen."""
    net = HighwayNet(maneuvers=sd["dec_lstm.weight_ih_l0"].shape[1] == 117)
    net.load_state_dict({k: torch.from_numpy(np.array(v, np.float32)) for k, v in sd.items()})
    net.eval()
    net.requires_grad_(False)  # the benchmark times input gradients only, like the JAX side
    return net


def torch_fns(sd: dict[str, np.ndarray], inputs, reference_mean: np.ndarray):
    """({"forward", "gradient"}: callables, max |torch - reference_mean| [m]) on the benchmark's
    compact SI inputs (hist [B, 16, 2], nbr_hist [B, N, 16, 2], slot [B, N], weight [B, N])."""
    hist_m, nbr_m, slot, _ = inputs
    b, n = slot.shape
    order = np.argsort(slot, axis=1, kind="stable")  # the reference wants grid-id order per sample
    slot_sorted = np.take_along_axis(slot, order, 1)
    nbr_sorted = np.take_along_axis(nbr_m, order[..., None, None], 1)
    hist = torch.from_numpy(np.asarray(si_to_model(hist_m), np.float32).transpose(1, 0, 2).copy())
    nbrs = np.asarray(si_to_model(nbr_sorted), np.float32).reshape(b * n, 16, 2).transpose(1, 0, 2)
    nbrs = torch.from_numpy(nbrs.copy())
    mask = np.zeros((b, 39, 64), bool)
    mask[np.arange(b)[:, None], slot_sorted] = True
    mask = torch.from_numpy(mask.reshape(b, 3, 13, 64))
    net = reference_net(sd)

    def mean_of(out):
        if not net.maneuvers:
            return out[..., :2]
        futs, lat, lon = out
        idx = lon.argmax(1) * 3 + lat.argmax(1)
        return torch.stack(futs)[idx, :, torch.arange(b)].transpose(0, 1)[..., :2]

    with torch.no_grad():
        mu = mean_of(net(hist, nbrs, mask)).numpy().transpose(1, 0, 2)  # [B, 25, 2] model frame
    agree = float(np.max(np.abs(np.asarray(model_to_si(mu)) - reference_mean)))

    def forward():
        with torch.no_grad():
            net(hist, nbrs, mask)

    def gradient():
        h = hist.clone().requires_grad_(True)
        nb = nbrs.clone().requires_grad_(True)
        mean_of(net(h, nb, mask)).sum().backward()

    return {"forward": forward, "gradient": gradient}, agree
