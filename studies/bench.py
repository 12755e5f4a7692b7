"""`python -m studies.bench`: our backends against the speed targets, on this machine.

Uniform scenes at the essay's density (r = 10, box side scaled by sqrt(n / 2048)); the measure is
the median per frame of the broad phase alone, `update` + `pairs`, single thread. Speed is
measured here and printed, never asserted: compare the ratios on your own machine.
"""

from __future__ import annotations

import sys

import numpy as np

from scenes.generate import at_essay_density
from scenes.motion import simulate

from .cli import CliError, Parser, run_cli
from .harness import Job, run_isolated

# ms per frame (update + pairs) that compiled code reaches on a 2-core machine of this kind.
TARGETS_MS = {
    2048: {"own.grid": 0.030, "own.sap": 0.120, "own.quadtree": 0.200},
    131072: {"own.grid": 4.0, "own.sap": 17.0, "own.quadtree": 25.0},
    1048576: {"own.grid": 40.0, "own.sap": 250.0, "own.quadtree": 300.0},
}
# "own.sap" is held to its best variant, as the targets say.
VARIANTS = {"own.grid": ["own.grid"], "own.sap": ["own.sap", "own.sap_incremental"], "own.quadtree": ["own.quadtree"]}


def broad_phase_ms(backend: str, traj) -> float:
    result = run_isolated(Job(backend, timeout_s=600.0), traj)
    if result.status != "ok":
        raise CliError(f"{backend} did not finish: {result.status}")
    return float(np.median([r["t_update_s"] + r["t_pairs_s"] for r in result.rows]) * 1e3)


def main(argv: list[str] | None = None) -> int:
    p = Parser(prog="python -m studies.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="only n = 2048")
    p.add_argument("--frames", type=int, default=10, help="timed frames per size (default 10)")
    args = p.parse_args(argv)
    if args.frames < 1:
        raise CliError("--frames must be at least 1")
    sizes = [2048] if args.quick else list(TARGETS_MS)
    print(f"{'n':>9} {'backend':<14} {'variant':<20} {'measured ms':>12} {'target ms':>10} {'measured/target':>16}")
    for n in sizes:
        # Fewer frames at a million objects: each frame's exact reference is itself costly.
        traj = simulate(at_essay_density("uniform", n), (args.frames if n <= 131072 else max(2, args.frames // 3)) + 1)
        for backend, target in TARGETS_MS[n].items():
            measured = {v: broad_phase_ms(v, traj) for v in VARIANTS[backend]}
            best = min(measured, key=measured.get)
            print(f"{n:>9} {backend:<14} {best:<20} {measured[best]:>12.3f} {target:>10.3f} "
                  f"{measured[best] / target:>15.1f}x")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("bench", main, None))
