"""Alias kept for callers that look for the collector next to the simulator.

The collector is orchestration (simulator + perception + dataset) and lives in
`lano3dp.data.collect`; the import is deferred so importing `lano3dp.sim` stays light.
"""

from __future__ import annotations


def collect(*args, **kwargs):
    """See `lano3dp.data.collect.collect`."""
    from lano3dp.data.collect import collect as _collect

    return _collect(*args, **kwargs)
