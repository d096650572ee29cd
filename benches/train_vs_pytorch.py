#!/usr/bin/env python3
"""PyTorch CPU counterpart of `tools/train/benches/train.rs`: the same training workload timed per epoch.

200k x 40 synthetic friction samples (2 signals x history 20, block-major, same generator formula as
`frictl::train::synthetic`), Linear(40,268)-ReLU-Dropout(0.1)-Linear(268,215)-ReLU-Dropout(0.1)-Linear(215,1),
loss (1-lam)*MSE(y, label) + lam*MSE(y, scv) with lam 0.1, Adam lr 1e-3, batch 4096 reshuffled each
epoch, inputs normalised by mean/IQR, 2 threads. Prints each epoch (wall and process CPU time),
then PYTORCH_EPOCH_S=<median wall s> and PYTORCH_EPOCH_CPU_S=<median CPU s> (first epoch excluded
when more than one runs).
"""
import argparse
import time

import numpy as np
import torch


def scv(v, fc=0.3, fs=0.5, vs=0.1, fv=0.2):
    return (fc + (fs - fc) * np.exp(-(v / vs) ** 2)) * np.sign(v) + fv * v


def friction_task(n, h, seed):
    rng = np.random.default_rng(seed)
    v_now = rng.uniform(-1, 1, n).astype(np.float32)
    acc = rng.uniform(-3, 3, n).astype(np.float32)
    i_now = rng.uniform(-1, 1, n).astype(np.float32)
    di = rng.uniform(-0.5, 0.5, n).astype(np.float32)
    k = np.arange(h - 1, -1, -1, dtype=np.float32)  # oldest -> newest
    vel = v_now[:, None] - acc[:, None] * 0.01 * k[None, :] + rng.normal(0, 0.01, (n, h)).astype(np.float32)
    cur = i_now[:, None] - di[:, None] * k[None, :] / h
    x = np.concatenate([vel, cur], axis=1).astype(np.float32)
    s = scv(v_now).astype(np.float32)
    y = (s + 0.1 * acc + 0.3 * i_now * np.abs(v_now) + rng.normal(0, 0.01, n)).astype(np.float32)
    return x, y, s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    x, y, s = friction_task(200_000, 20, 1)
    mean = x.mean(0)
    iqr = np.percentile(x, 75, axis=0) - np.percentile(x, 25, axis=0)
    iqr[iqr <= 1e-4] = 1.0
    x = torch.from_numpy((x - mean) / iqr)
    y = torch.from_numpy(y)[:, None]
    s = torch.from_numpy(s)[:, None]
    model = torch.nn.Sequential(
        torch.nn.Linear(40, 268), torch.nn.ReLU(), torch.nn.Dropout(0.1),
        torch.nn.Linear(268, 215), torch.nn.ReLU(), torch.nn.Dropout(0.1),
        torch.nn.Linear(215, 1),
    )
    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    lam, batch, n = 0.1, 4096, x.shape[0]
    secs, cpu_secs = [], []
    for epoch in range(1, args.epochs + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        perm = torch.randperm(n)
        total = 0.0
        for start in range(0, n, batch):
            idx = perm[start:start + batch]
            xb, yb, sb = x[idx], y[idx], s[idx]
            opt.zero_grad(set_to_none=True)
            out = model(xb)
            loss = (1 - lam) * torch.mean((out - yb) ** 2) + lam * torch.mean((out - sb) ** 2)
            loss.backward()
            opt.step()
            total += loss.item() * idx.shape[0]
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        secs.append(dt)
        cpu_secs.append(dc)
        print(f"epoch {epoch:3d}: {dt:.3f} s  (CPU {dc:.3f} s, all threads)  train loss {total / n:.5f}", flush=True)

    def median(v):
        v = sorted(v[1:] if len(v) > 1 else v)
        return v[len(v) // 2]

    print(f"PYTORCH_EPOCH_S={median(secs):.4f}")
    print(f"PYTORCH_EPOCH_CPU_S={median(cpu_secs):.4f}")
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}")


if __name__ == "__main__":
    main()
