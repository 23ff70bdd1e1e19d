"""CNN surrogate benchmark: inference at batch 1 per width, grid and memory layout; one training
step at 32x32x64, batch 4; peak memory. Writes benchmarks/results/cnn.md.

    python benchmarks/cnn.py [--grids 17x17x33 33x33x65 64x64x128] [--widths 8 16 32] [--repeat 5]

Each malloc setting runs in its own child process (glibc reads MALLOC_* only at start-up), so
"plain" and "tuned" (MALLOC_MMAP_MAX_=0 MALLOC_TRIM_THRESHOLD_=64 GiB) are compared side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

TUNED_MALLOC = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": "68719476736"}
RESULTS = Path(__file__).resolve().parent / "results"


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _median_time(fn, repeat: int) -> float:  # type: ignore[no-untyped-def]
    fn()  # warm-up: oneDNN primitive creation, first-touch allocation
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


# inference variants: (name, memory layout, call oneDNN directly for small batch-1 convs)
VARIANTS = (("native", False, False), ("cl3d", True, False), ("direct", False, True),
            ("direct_cl3d", True, True))  # fmt: skip


def child(args: argparse.Namespace) -> dict:
    import torch

    from diathermy.surrogates import layers
    from diathermy.surrogates.cnn import CNNConfig, DisplacementCNN
    from diathermy.surrogates.losses import l2_loss

    torch.set_num_threads(args.threads[-1])
    torch.manual_seed(0)
    shipped_threshold = layers._ONEDNN_THRESHOLD
    rows = []
    for grid in args.grids:
        for width in args.widths:
            model = DisplacementCNN(CNNConfig(width=width)).eval()
            x = torch.randn(1, 2, *grid)
            row = {"grid": "x".join(map(str, grid)), "width": width}
            for name, cl, direct in VARIANTS:
                fmt = torch.channels_last_3d if cl else torch.contiguous_format
                m = model.to(memory_format=fmt)
                xi = x.contiguous(memory_format=fmt)
                layers._ONEDNN_THRESHOLD = shipped_threshold if direct else -1

                def run(m=m, xi=xi) -> None:  # type: ignore[no-untyped-def]
                    with torch.inference_mode():
                        m(xi)

                row[name] = _median_time(run, args.repeat)
            layers._ONEDNN_THRESHOLD = shipped_threshold
            row["peak_rss_mb"] = _peak_rss_mb()
            rows.append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
    train_rows = []
    for width in args.train_widths:
        model = DisplacementCNN(CNNConfig(width=width))
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
        x = torch.randn(4, 2, *args.train_grid)
        y = torch.randn(4, 3, *args.train_grid)
        row = {"width": width}
        for layout in ("native", "cl3d"):
            fmt = torch.channels_last_3d if layout == "cl3d" else torch.contiguous_format
            m = model.to(memory_format=fmt)
            xi, yi = x.contiguous(memory_format=fmt), y.contiguous(memory_format=fmt)

            def step(m=m, xi=xi, yi=yi, opt=opt) -> None:  # type: ignore[no-untyped-def]
                opt.zero_grad(set_to_none=True)
                l2_loss(m(xi), yi).backward()
                opt.step()

            row[layout] = _median_time(step, max(2, args.repeat // 2))
        row["peak_rss_mb"] = _peak_rss_mb()
        train_rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    return {"inference": rows, "training": train_rows, "threads": torch.get_num_threads(),
            "torch": torch.__version__}  # fmt: skip


def parse_grid(text: str) -> tuple[int, int, int]:
    nz, ny, nx = (int(v) for v in text.lower().split("x"))
    return nz, ny, nx


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grids", nargs="+", type=parse_grid,
                    default=[(17, 17, 33), (33, 33, 65), (64, 64, 128)])  # fmt: skip
    ap.add_argument("--widths", nargs="+", type=int, default=[8, 16, 32])
    ap.add_argument("--train-widths", nargs="+", type=int, default=[8, 16, 32])
    ap.add_argument("--train-grid", type=parse_grid, default=(32, 32, 64))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2], help="torch threads")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", default=str(RESULTS / "cnn.md"))
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args)))
        return
    argv = sys.argv[1:]
    results = {}
    for threads in args.threads:
        for name, extra in (("plain", {}), ("tuned", TUNED_MALLOC)):
            env = {k: v for k, v in os.environ.items() if k not in TUNED_MALLOC} | extra
            print(f"== malloc {name}, {threads} threads", file=sys.stderr, flush=True)
            cmd = [sys.executable, __file__, *argv, "--child", "--threads", str(threads)]
            proc = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=True)
            results[(threads, name)] = json.loads(proc.stdout.strip().splitlines()[-1])
    write_report(results, args)


def write_report(results: dict, args: argparse.Namespace) -> None:
    any_run = next(iter(results.values()))
    lines = [
        "# CNN surrogate benchmark",
        "",
        f"`python benchmarks/cnn.py` on {platform.machine()}, {os.cpu_count()} cores visible "
        f"(shared with other jobs: load was high, so treat single numbers as +-30 %), torch "
        f"{any_run['torch']}; median of {args.repeat} repeats after one warm-up. Variants: "
        "`native` = plain `F.conv3d` (what PyTorch picks: its generic path for batch-1 convs with "
        "N*C*D*H <= 20480), `cl3d` = model and input in channels_last_3d, `direct` = the shipped "
        "inference path (`layers.conv3d_same` calls oneDNN itself for those convs), "
        "`direct_cl3d` = both. Malloc: plain glibc vs tuned (`MALLOC_MMAP_MAX_=0 "
        "MALLOC_TRIM_THRESHOLD_=68719476736`), each in its own process. Peak RSS is the whole "
        "benchmark process so far (resource.getrusage).",
    ]
    names = [v[0] for v in VARIANTS]
    for (threads, malloc), res in results.items():
        lines += [
            "",
            f"## Inference, batch 1, {threads} thread(s), {malloc} malloc (seconds per call)",
            "",
            "| grid | width | " + " | ".join(names) + " | native / direct | native / cl3d | "
            "peak RSS MB |",
            "|---|---|" + "---|" * (len(names) + 3),
        ]
        for r in res["inference"]:
            lines.append(
                f"| {r['grid']} | {r['width']} | "
                + " | ".join(f"{r[n]:.4f}" for n in names)
                + f" | {r['native'] / r['direct']:.1f}x | {r['native'] / r['cl3d']:.2f}x"
                f" | {r['peak_rss_mb']:.0f} |"
            )
    grid = "x".join(map(str, args.train_grid))
    lines += [
        "",
        f"## Training step (forward + backward + Adam), {grid}, batch 4 (seconds)",
        "",
        "| threads | malloc | width | native | cl3d | native / cl3d | peak RSS MB |",
        "|---|---|---|---|---|---|---|",
    ]
    for (threads, malloc), res in results.items():
        for r in res["training"]:
            lines.append(
                f"| {threads} | {malloc} | {r['width']} | {r['native']:.3f} | {r['cl3d']:.3f} | "
                f"{r['native'] / r['cl3d']:.2f}x | {r['peak_rss_mb']:.0f} |"
            )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
