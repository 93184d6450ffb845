"""Episode storage (zarr) and windowed sequence sampling for training."""

from lano3dp.data.sequence import SequenceDataset, split_episodes
from lano3dp.data.store import EpisodeStore

__all__ = ["EpisodeStore", "SequenceDataset", "split_episodes"]
