"""The policy's target clouds over an episode, kept as a video tracker would keep them.

A target that is momentarily hidden (too few points: the pan under the tilted bowl, or behind an obstacle) keeps
its previous cloud, as the demonstrations were recorded (`lano3dp.collect`). In the first frame a target with only
a few points in view is taken from those; one not in view at all is looked for in the env's other views
(`OtherViews`) and taken from there whenever the observation camera cannot see it; one seen nowhere is an error the
caller sees.

A frame the policy never observes (between two chunks) need not be perceived: `defer` keeps how to render it, and
it is perceived only when a later frame needs what it would have held (a target hidden there), in order, so every
cloud the policy sees is the one perceiving every frame gives. Only where perception depends on the frame alone
(the segmenter's `per_frame`) and no target is followed in the env's other views, which show the present moment.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.exceptions import ObjectNotFoundError, PerceptionError, TooFewPointsError
from lano3dp.perception.observer import ObjectObserver
from lano3dp.perception.views import OtherViews

# Points enough for a first-frame target cloud that an obstacle mostly hides (FPS repeats them to N): its
# centroid is still the object's, where failing the episode would be certain.
FIRST_FRAME_MIN_POINTS = 3


class TargetClouds:
    """(K, N, 3) target clouds in slot order, frame by frame, with what was held or found elsewhere."""

    def __init__(self, observer: ObjectObserver, views: OtherViews):
        self.observer = observer
        self.views = views
        self.reset()

    def reset(self) -> None:
        self.last: np.ndarray | None = None
        self.deferred: list[tuple[Callable[[], RGBDFrame], int]] = []  # frames not perceived yet, and their steps
        self.held_clouds = 0  # frames perceived in which a hidden target kept its previous cloud
        self.partly_hidden: list[str] = []  # targets taken from a few points in the first frame
        self.initial_targets: dict[str, list[float]] = {}  # phrase -> centroid (m) in the first frame

    def can_defer(self, phrases: Sequence[str]) -> bool:
        """Whether the next frame may be left unperceived until a later one needs it (see the module)."""
        per_frame = getattr(self.observer.segmenter, "per_frame", None)
        return self.last is not None and not self.views.seen and per_frame is not None and per_frame(phrases)

    def defer(self, frame: Callable[[], RGBDFrame], step: int) -> None:
        """A frame no window will hold, as a callable that renders it: perceived later only if needed."""
        self.deferred.append((frame, step))

    def __call__(self, frame: RGBDFrame, phrases: Sequence[str], *, step: int) -> np.ndarray:
        if self.deferred:
            try:  # every target in view: the frames before this one change nothing
                clouds = self.observer.observe(frame, phrases).points
            except PerceptionError:  # one is hidden: it keeps what the frames before held, so perceive them first
                deferred, self.deferred = self.deferred, []
                for earlier, at in deferred:
                    self._perceive(earlier(), phrases, at)
            else:
                self.deferred.clear()
                self.last = clouds
                return clouds
        return self._perceive(frame, phrases, step)

    def _perceive(self, frame: RGBDFrame, phrases: Sequence[str], step: int) -> np.ndarray:
        try:
            clouds = self.observer.observe(frame, phrases).points
        except PerceptionError:
            if self.last is None:
                clouds = np.stack([self._first_cloud(frame, phrase, step) for phrase in phrases])
            else:
                clouds = []
                for slot, phrase in enumerate(phrases):
                    try:
                        clouds.append(self.observer.observe(frame, [phrase]).points[0])
                    except PerceptionError as hidden:
                        clouds.append(self._hidden_cloud(slot, phrase, hidden, step))
                clouds = np.stack(clouds)
        if self.last is None:
            self.initial_targets = {phrase: clouds[k].mean(0).round(4).tolist() for k, phrase in enumerate(phrases)}
        self.last = clouds
        return clouds

    def _first_cloud(self, frame: RGBDFrame, phrase: str, step: int) -> np.ndarray:
        """A target the obstacle mostly hides in the first frame is taken from the few points still in view
        (FIRST_FRAME_MIN_POINTS) rather than failing the episode: there is no earlier cloud. One with fewer
        still, or none, is looked for in the other views."""
        try:
            return self.observer.observe(frame, [phrase]).points[0]
        except TooFewPointsError:
            pass
        except ObjectNotFoundError as not_found:
            return self.views.observe(phrase, not_found, step=step).points[0]
        try:
            cloud = self.observer.observe(frame, [phrase], min_points=FIRST_FRAME_MIN_POINTS).points[0]
        except TooFewPointsError as hidden:
            return self.views.observe(phrase, hidden, step=step).points[0]
        self.partly_hidden.append(phrase)
        return cloud

    def _hidden_cloud(self, slot: int, phrase: str, hidden: PerceptionError, step: int) -> np.ndarray:
        """A target the camera cannot see after the first frame: from the other views if it was first found
        there (the camera may never see it: it stands behind the obstacle), else its previous cloud."""
        if phrase in self.views.seen:
            try:
                return self.views.observe(phrase, hidden, step=step).points[0]
            except PerceptionError:
                pass
        self.held_clouds += 1
        return self.last[slot]
