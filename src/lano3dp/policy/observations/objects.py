"""obs_type "objects" (Lan-o3dp): one point cloud per named object slot, (K, N, 3) per step, key "object_clouds".

Recorded through the observer (ground-truth segmentation, FPS to N points); a slot hidden in a frame (too few points,
e.g. the pan under the tilted bowl) keeps its cloud from the previous frame, as a video tracker would hold it, and
an episode whose first frame misses a slot is not recorded. At run time `PolicyRunner.object_clouds` does the same.
"""

from __future__ import annotations

import numpy as np

from lano3dp.perception import PerceptionError
from lano3dp.policy.encoders import ObjectCloudsEncoder
from lano3dp.policy.observations import ObservationType, RecordContext, UnrecordableEpisode


class ObjectCloudsRecorder:
    """One episode's object clouds, holding a hidden slot's previous cloud; `held` counts those slot-frames."""

    def __init__(self, context: RecordContext):
        self.observer, self.phrases = context.observer, list(context.phrases)
        self.last: list[np.ndarray | None] = [None] * len(self.phrases)
        self.held = 0

    def __call__(self, frame) -> np.ndarray:
        try:
            clouds = list(self.observer.observe(frame, self.phrases).points)
        except PerceptionError:  # some slot is occluded: hold its last cloud
            clouds = []
            for k, phrase in enumerate(self.phrases):
                try:
                    clouds.append(self.observer.observe(frame, [phrase]).points[0])
                except PerceptionError:
                    if self.last[k] is None:
                        raise UnrecordableEpisode(f"{phrase!r} is not in view in the first frame") from None
                    clouds.append(self.last[k])
                    self.held += 1
        self.last = clouds
        return np.stack(clouds).astype(np.float32)


class ObjectCloudsObservation(ObservationType):
    key = "object_clouds"
    object_slots = True

    def encoder(self, config):
        return ObjectCloudsEncoder(config)

    def runtime_input(self, runner, frame):
        return runner.object_clouds(frame)  # the runner keeps the hold-last-cloud state and the first centroids

    def recorder(self, context):
        return ObjectCloudsRecorder(context)

    def normalizer_dim(self, config):
        return 3  # one xyz range shared by all slots and points, so the objects' relative layout is kept

    def cloud_points(self, config):
        return config.n_points

    def dataset_fields(self, step_shape):
        return {"n_points": step_shape[1]}

    def validate(self, config):
        if len(config.object_names) < 1:
            raise ValueError("obs_type 'objects' needs object_names (the slot order)")
        if len(set(config.object_names)) != len(config.object_names):
            raise ValueError(f"object_names must be distinct, got {config.object_names}")
