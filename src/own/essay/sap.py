"""The essay's sweep and prune: x axis only, sorted interval ends and an active list, no y filter."""

from __future__ import annotations

from .particle import EssayBroadPhase, Particle, ordered

START, END = 0, 1  # at equal coordinates starts come first, so touching intervals overlap


class EssaySweepAndPrune(EssayBroadPhase):
    """Reports every pair whose x intervals overlap; the narrow phase absorbs the rest."""

    name = "essay.sap"
    method = "sweep"

    def _find(self, particles: list[Particle]) -> set[tuple[int, int]]:
        ends = [(p.x - p.r, START, p.index, p) for p in particles]
        ends += [(p.x + p.r, END, p.index, p) for p in particles]
        ends.sort(key=lambda e: (e[0], e[1], e[2]))
        active: list[Particle] = []
        found: set[tuple[int, int]] = set()
        for _, kind, _, p in ends:
            if kind == START:
                for q in active:
                    found.add(ordered(p, q))
                active.append(p)
            else:
                active.remove(p)
        self._stats = {"tests": len(found)}
        return found

