"""Chunk filters: what runs on a guided sample before it executes, one file each (`base` has the protocol).

    repair    push the path the arm will take clear of the margin by plain descent
    hold      execute only the start predicted to keep half the margin; hold still when none does
    escape    (after hold) a hand already inside half the margin moves away, or steps straight out
    follow    (after hold) a hand held still for several chunks follows the nearest obstacle's boundary
"""

from lano3dp.guidance.execution.base import (
    _FILTERS,
    ChunkFilter,
    FilterContext,
    FilterResult,
    NoOptions,
    Proposal,
    UnknownChunkFilterError,
    build_filters,
    check_filters,
    chunk_filter_names,
    filters_for_workers,
    register_chunk_filter,
    register_worker_filters,
    run_filters,
)
from lano3dp.guidance.execution.escape import Escape
from lano3dp.guidance.execution.follow import Follow
from lano3dp.guidance.execution.hold import Hold
from lano3dp.guidance.execution.repair import Repair

_FILTERS.mark_builtin()

__all__ = ["ChunkFilter", "Escape", "FilterContext", "FilterResult", "Follow", "Hold", "NoOptions", "Proposal",
           "Repair", "UnknownChunkFilterError", "build_filters", "check_filters", "chunk_filter_names",
           "filters_for_workers", "register_chunk_filter", "register_worker_filters", "run_filters"]
