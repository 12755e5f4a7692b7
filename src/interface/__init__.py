"""The ground floor: the interface every broad phase implements (`BroadPhase`), the registry of
backends, the knobs a study sweeps, the pair format and the checks at the boundary. It imports
nothing of the project's above it; our algorithms (`own`), the engines' adapters (`engines`), the
scenes and the studies all stand on it."""

from .kernel_cache import drop_stale_kernels

drop_stale_kernels()  # before any kernel of the project is loaded from numba's cache
