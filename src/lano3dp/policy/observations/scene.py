"""obs_type "scene" (the DP3 baseline): the whole cropped scene cloud without the table, (N, 3) per step, key
"scene_cloud"."""

from __future__ import annotations

from lano3dp.perception import scene_cloud
from lano3dp.policy.encoders import SceneCloudEncoder
from lano3dp.policy.observations import ObservationType


class SceneCloudObservation(ObservationType):
    key = "scene_cloud"

    def encoder(self, config):
        return SceneCloudEncoder(config)

    def runtime_input(self, runner, frame):
        observer = runner.observer  # its crop box is the one the dataset was recorded with
        low = None if observer is None else observer.crop_low
        high = None if observer is None else observer.crop_high
        return scene_cloud(frame, n_points=runner.policy_config.scene_points, crop_low=low, crop_high=high)

    def recorder(self, context):
        s = context.settings
        return lambda frame: scene_cloud(frame, s.scene_points, s.crop_low, s.crop_high,
                                         table_height=s.table_height).astype("float32")

    def normalizer_dim(self, config):
        return 3

    def cloud_points(self, config):
        return config.scene_points

    def dataset_fields(self, step_shape):
        return {"scene_points": step_shape[0]}
