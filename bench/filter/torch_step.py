#!/usr/bin/env python3
"""bench/filter's PyTorch peer: one SeqLoc step as a PyTorch user would write it from the paper.

Motion and crop intake by grid_sample, log_softmax for the frame, logsumexp for the
normalization, logaddexp for MGR, a local expectation for PAS; eager mode, float32, the belief
in log-probabilities, R x H x W. It is the peer that `scripts/bench filter --device cuda` measures
DeviceFilter against on the same GPU in the same run (docs/gpu.md), not a second implementation
of seqloc: no self-calibration, no sub-bin heading, the crop axis-aligned.

    bench/filter/torch_step.py --size 256 --device cuda

prints the median ms of a step and ends with one line of JSON.
"""
import argparse
import json
import math
import time

import torch
import torch.nn.functional as F

CELL_M = 0.5


def predict(log_b, forward_m, left_m, yaw_deg):
    """Each heading slice moved by the odometry turned into its heading, then the bins rolled by the yaw."""
    R, H, W = log_b.shape
    heading = torch.arange(R, device=log_b.device, dtype=torch.float32) * (2 * math.pi / R)
    du = (forward_m * torch.sin(heading) - left_m * torch.cos(heading)) / CELL_M
    dv = -(forward_m * torch.cos(heading) + left_m * torch.sin(heading)) / CELL_M
    theta = torch.zeros(R, 2, 3, device=log_b.device)
    theta[:, 0, 0] = 1
    theta[:, 1, 1] = 1
    theta[:, 0, 2] = -du * 2 / (W - 1)
    theta[:, 1, 2] = -dv * 2 / (H - 1)
    grid = F.affine_grid(theta, (R, 1, H, W), align_corners=True)
    moved = F.grid_sample(log_b.exp().unsqueeze(1), grid, align_corners=True).squeeze(1)
    shift = yaw_deg * R / 360
    whole = math.floor(shift)
    a = shift - whole
    turned = (1 - a) * torch.roll(moved, -whole, 0) + a * torch.roll(moved, -whole - 1, 0)
    return torch.log(turned.clamp_min(1e-38))


def intake(frame_logits, size_hw, centre_uv, outside_nats=1.0, reference_entropy=0.9):
    """The frame's log-probabilities, tempered by ETU, sampled at every window cell and bin."""
    N, h, w = frame_logits.shape
    H, W = size_hw
    log_p = F.log_softmax(frame_logits.reshape(-1), 0).reshape(N, h, w)
    cells = N * h * w
    entropy = -(log_p.exp() * log_p).sum() / math.log(cells)
    weight = ((1 - entropy) / (1 - reference_entropy)).clamp(1e-3, 1)
    cu, cv = centre_uv
    theta = torch.zeros(N, 2, 3, device=frame_logits.device)
    theta[:, 0, 0] = (W - 1) / (w - 1)
    theta[:, 0, 2] = 2 * ((W - 1) / 2 - cu + (w - 1) / 2) / (w - 1) - 1
    theta[:, 1, 1] = (H - 1) / (h - 1)
    theta[:, 1, 2] = 2 * ((H - 1) / 2 - cv + (h - 1) / 2) / (h - 1) - 1
    grid = F.affine_grid(theta, (N, 1, H, W), align_corners=True)
    sampled = F.grid_sample(log_p.unsqueeze(1), grid, align_corners=True, padding_mode="border").squeeze(1)
    inside = (grid.abs() <= 1).all(-1)
    outside = -math.log(cells) - outside_nats
    return weight * torch.where(inside, sampled, torch.full_like(sampled, outside))


def step(log_b, frame_logits, odometry, centre_uv, log_q, eps=0.01, pas_radius=3):
    R, H, W = log_b.shape
    log_b = predict(log_b, *odometry)
    log_b = log_b + intake(frame_logits, (H, W), centre_uv)
    log_b = log_b - torch.logsumexp(log_b.reshape(-1), 0)
    log_b = torch.logaddexp(log_b + math.log(1 - eps), log_q + math.log(eps))
    flat = int(torch.argmax(log_b))
    k, v, u = flat // (H * W), flat // W % H, flat % W
    mass = log_b.exp().sum(0)
    v0, v1 = max(v - pas_radius, 0), min(v + pas_radius + 1, H)
    u0, u1 = max(u - pas_radius, 0), min(u + pas_radius + 1, W)
    patch = mass[v0:v1, u0:u1]
    vs = torch.arange(v0, v1, device=log_b.device, dtype=torch.float32)
    us = torch.arange(u0, u1, device=log_b.device, dtype=torch.float32)
    total = patch.sum()
    pose = ((patch.sum(0) * us).sum() / total, (patch.sum(1) * vs).sum() / total, k)
    return log_b, pose


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=256, help="window cells each way (headings: --headings)")
    parser.add_argument("--headings", type=int, default=256)
    parser.add_argument("--frame", type=int, default=128, help="frame cells each way (its bins: --headings)")
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    torch.manual_seed(42)
    dev = torch.device(args.device)
    R, S = args.headings, args.size
    log_b = torch.full((R, S, S), -math.log(R * S * S), device=dev)
    frame = torch.randn(R, args.frame, args.frame, device=dev) * 2
    road = (torch.arange(S, device=dev, dtype=torch.float32) - S / 2).abs().mul(CELL_M).expand(S, S)
    g = torch.exp(-road**2 / (2 * 3.0**2))
    log_q = torch.log((0.9 * g / g.sum() + 0.1 / (S * S)) / R).unsqueeze(0)

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize()

    times = []
    for i in range(args.repeats + 3):
        sync()
        t0 = time.perf_counter()
        log_b, pose = step(log_b, frame, (3.7, 0.2, 4.3), (S / 2 + i % 3, S / 2 - i % 2), log_q)
        float(pose[0])  # the pose reaches the host, as a localizer's does
        sync()
        if i >= 3:
            times.append((time.perf_counter() - t0) * 1000)
    times.sort()
    ms = times[len(times) // 2]
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else "cpu"
    print(f"PyTorch {torch.__version__} on {name}: {S}x{S}x{R} window, {args.frame}^2 x {R} frame: {ms:.2f} ms a step")
    print(json.dumps({"peer": "pytorch_step", "torch": torch.__version__, "device": name, "window": S,
                      "headings": R, "ms_per_step": round(ms, 3)}))


if __name__ == "__main__":
    main()
