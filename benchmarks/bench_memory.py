"""Benchmark: device memory of a Reconstructor, in bytes per voxel of its grid.

For each grid (the octant scene at ``resolution=N``, default options), a Reconstructor is built and
run for ``--iterations`` steps with measures (so every scratch array the iteration uses exists),
and its memory is counted three ways:

- held: the ``nbytes`` of every ``wp.array`` reachable from the solver's attributes (its
  redistancer, structs, lists and dicts included), each allocation counted once;
- peak: the high-water mark of Warp's allocation tracker (``wp.ScopedMemoryTracker``) over the
  construction and the run, transient arrays included;
- on CUDA also: the growth of the memory pool's current use
  (``wp.get_mempool_used_mem_current``), its high-water mark minus the use before, and the drop
  of ``device.free_memory``.

Host copies of grid-sized NumPy arrays that the solver keeps are listed apart (not device
memory on CUDA; on the CPU they share the same RAM).

    python benchmarks/bench_memory.py [--sizes 64 128] [--device cpu]
"""

from __future__ import annotations

import argparse
import gc
import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OCTANT = ROOT / "examples" / "scenes" / "octant.json"

UNITS = {"B": 1, "bytes": 1, "KB": 2**10, "MB": 2**20, "GB": 2**30, "TB": 2**40}


def _walkable(obj) -> bool:
    """Walk warpspec's own objects and Warp struct instances, nothing else."""
    module = type(obj).__module__ or ""
    return module.startswith("warpspec") or any(
        c.__name__ == "StructInstance" for c in type(obj).__mro__)


def held_arrays(root) -> tuple[list[tuple[str, object]], list[tuple[str, np.ndarray]]]:
    """Every ``wp.array`` and every NumPy array reachable from ``root``'s attributes.

    Returns:
        ``(path, array)`` pairs for the Warp arrays (one per allocation: views that point into
        an allocation already seen are dropped) and for the NumPy arrays.
    """
    import warp as wp

    found: list[tuple[str, object]] = []
    host: list[tuple[str, np.ndarray]] = []
    seen: set[int] = set()

    def visit(obj, path: str, depth: int) -> None:
        if id(obj) in seen or depth > 8:
            return
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            found.append((path, obj))
        elif isinstance(obj, np.ndarray):
            host.append((path, obj))
        elif isinstance(obj, dict):
            for key, value in obj.items():
                visit(value, f"{path}[{key!r}]", depth + 1)
        elif isinstance(obj, list | tuple | set):
            for n, value in enumerate(obj):
                visit(value, f"{path}[{n}]", depth + 1)
        elif hasattr(obj, "__dict__") and _walkable(obj):
            for name, value in vars(obj).items():
                visit(value, f"{path}.{name}", depth + 1)

    visit(root, "solver", 0)
    # one entry per allocation: drop arrays whose memory lies inside one already counted
    found.sort(key=lambda pa: -_span(pa[1]))
    unique, spans = [], []
    for path, arr in found:
        if arr.ptr is None or arr.ptr == 0:
            continue
        lo, hi = arr.ptr, arr.ptr + _span(arr)
        if any(a <= lo and hi <= b for a, b in spans):
            continue
        spans.append((lo, hi))
        unique.append((path, arr))
    return unique, host


def _span(arr) -> int:
    """Bytes of an array's allocation (``capacity``; ``size * element size`` if unset)."""
    import warp as wp

    return int(arr.capacity or arr.size * wp.types.type_size_in_bytes(arr.dtype))


def parse_peak(report: str, device: str) -> int | None:
    """The peak bytes of ``device`` in a Warp allocation tracker report, if present."""
    block = report.split("Peak usage:", 1)
    if len(block) < 2:
        return None
    for line in block[1].splitlines()[1:]:
        if not line.startswith(" "):
            break
        m = re.match(r"\s+(\S+)\s+([\d.]+)\s*([KMGT]?B|bytes)\s*$", line)
        if m and m.group(1) == device:
            return int(float(m.group(2)) * UNITS[m.group(3)])
    return None


def measure(size: int, *, device, iterations: int) -> dict:
    """Count the memory of one Reconstructor at one size."""
    import warp as wp

    import warpspec as ws

    gc.collect()
    cuda = device.is_cuda
    if cuda:
        wp.synchronize_device(device)
        pool_before = wp.get_mempool_used_mem_current(device)
        free_before = device.free_memory
    reports: list[str] = []
    with wp.ScopedMemoryTracker(f"reconstructor-{size}", print=False,
                                report_func=reports.append) as tracker:
        solver = ws.Reconstructor(ws.Scene.load(OCTANT), resolution=size,
                                  device=device)
        solver.run(iterations, measure_every=1)
        wp.synchronize_device(device)
        tracker.report()
    voxels = solver.grid.size
    arrays, host = held_arrays(solver)
    row = {
        "size": size,
        "shape": list(solver.grid.shape),
        "voxels": voxels,
        "arrays": len(arrays),
        "held_bytes": sum(_span(a) for _, a in arrays),
        "tracker_peak_bytes": parse_peak(reports[-1] if reports else "", device.alias),
        "host_grid_bytes": sum(a.nbytes for _, a in host if a.size >= voxels),
        "listing": [
            {"path": p, "dtype": getattr(a.dtype, "__name__", str(a.dtype)),
             "shape": list(a.shape), "bytes": _span(a)} for p, a in arrays
        ],
        "host_listing": [{"path": p, "dtype": str(a.dtype), "shape": list(a.shape),
                          "bytes": a.nbytes} for p, a in host if a.size >= voxels],
    }
    if cuda:
        wp.synchronize_device(device)
        row["pool_current_bytes"] = wp.get_mempool_used_mem_current(device) - pool_before
        row["pool_high_bytes"] = wp.get_mempool_used_mem_high(device) - pool_before
        row["free_drop_bytes"] = free_before - device.free_memory
    del solver, arrays, host
    gc.collect()
    return row


def _per_voxel(value: int | None, voxels: int) -> str:
    return "n/a" if value is None else f"{value / voxels:.1f}"


def tables(rows: list[dict], cuda: bool) -> str:
    """Markdown tables of :func:`measure`'s rows."""
    head = ("| grid | voxels | wp.arrays held | held (B/voxel) | tracked peak (B/voxel) ")
    rule = "|---|---|---|---|---"
    if cuda:
        head += "| mempool growth (B/voxel) | mempool high-water (B/voxel) | free_memory drop "
        head += "(B/voxel) "
        rule += "|---|---|---"
    head += "| host grid copies (B/voxel) |"
    rule += "|---|"
    lines = [head, rule]
    for r in rows:
        v = r["voxels"]
        line = (f"| {r['size']}^3 ({'x'.join(map(str, r['shape']))}) | {v / 1e6:.2f} M "
                f"| {r['arrays']} | {_per_voxel(r['held_bytes'], v)} "
                f"| {_per_voxel(r['tracker_peak_bytes'], v)} ")
        if cuda:
            line += (f"| {_per_voxel(r['pool_current_bytes'], v)} "
                     f"| {_per_voxel(r['pool_high_bytes'], v)} "
                     f"| {_per_voxel(r['free_drop_bytes'], v)} ")
        line += f"| {_per_voxel(r['host_grid_bytes'], v)} |"
        lines.append(line)
    if rows:
        r = rows[-1]
        v = r["voxels"]
        lines += ["", f"What the solver holds at {r['size']}^3 (arrays of at least 0.01 B/voxel):",
                  "", "| attribute | dtype | shape | B/voxel |", "|---|---|---|---|"]
        for item in sorted(r["listing"], key=lambda x: -x["bytes"]):
            if item["bytes"] >= 0.01 * v:
                lines.append(f"| `{item['path']}` | {item['dtype']} "
                             f"| {'x'.join(map(str, item['shape']))} "
                             f"| {item['bytes'] / v:.2f} |")
        for item in r["host_listing"]:
            lines.append(f"| `{item['path']}` (host NumPy) | {item['dtype']} "
                         f"| {'x'.join(map(str, item['shape']))} | {item['bytes'] / v:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["64", "128"], help="grid resolutions")
    parser.add_argument("--iterations", type=int, default=20,
                        help="steps run before counting (with measures)")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0)")
    parser.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)

    import warp as wp

    from warpspec._runtime import resolve_device

    device = resolve_device(args.device)
    sizes = [int(v) for item in args.sizes for v in str(item).split(",") if v]
    rows = [measure(n, device=device, iterations=args.iterations) for n in sizes]
    print(f"Octant scene at resolution N, default options, after {args.iterations} iterations with "
          f"measures; warp {wp.__version__}, device {device.alias} ({device.name}). "
          "B/voxel = bytes / nodes of the grid.")
    print()
    print(tables(rows, device.is_cuda))
    if args.json:
        Path(args.json).write_text(json.dumps({"device": device.alias, "rows": rows}, indent=1))
    return rows


if __name__ == "__main__":
    main()
