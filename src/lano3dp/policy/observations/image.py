"""obs_type "image" (the Diffusion Policy baseline): a square RGB image, (S, S, 3) uint8 per step, key "rgb".

Not normalised by the policy: the encoder scales the uint8 values to [-1, 1] itself, and the images get no
geometric augmentation (a moved scene would need a re-render).
"""

from __future__ import annotations

from lano3dp.geometry.frame import resize_rgb
from lano3dp.policy.encoders import ImageEncoder
from lano3dp.policy.observations import ObservationType


class ImageObservation(ObservationType):
    key = "rgb"
    needs_rgb = True

    def encoder(self, config):
        return ImageEncoder(config)

    def runtime_input(self, runner, frame):
        return resize_rgb(frame.rgb, runner.policy_config.image_size)

    def recorder(self, context):
        size = context.settings.rgb_size
        return lambda frame: resize_rgb(frame.rgb, size)

    def dataset_fields(self, step_shape):
        return {"image_size": step_shape[0]}
