"""Looking for an object in the env's other calibrated cameras when the observation camera cannot see it.

An obstacle can hide a whole target from the front camera in the first frame, or one obstacle another. An env with
more cameras offers them through its optional `other_views()` (`sim.protocol`); they are rendered only when asked,
at most once per step however many objects are looked for.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.exceptions import PerceptionError
from lano3dp.perception.observer import ObjectClouds, ObjectObserver

OtherViewsFn = Callable[[], Sequence[RGBDFrame]]


class OtherViews:
    """The env's other views of one episode, and what was found only there (`seen`)."""

    def __init__(self, observer: ObjectObserver, render: OtherViewsFn | None = None):
        self.observer = observer
        self.reset(render)

    def reset(self, render: OtherViewsFn | None) -> None:
        """A new episode: `render` gives this moment from the env's other cameras (None: it has none)."""
        self.render = render
        self.seen: list[str] = []  # phrases the observation camera missed, found in another view
        self._rendered: tuple[int, list[RGBDFrame]] | None = None  # (step, views rendered at it)

    def frames(self, step: int) -> list[RGBDFrame]:
        """The other views at env step `step`, rendered once per step."""
        if self.render is None:
            return []
        if self._rendered is None or self._rendered[0] != step:
            self._rendered = (step, list(self.render()))
        return self._rendered[1]

    def observe(self, phrase: str, hidden: PerceptionError, *, step: int, instances: bool = False) -> ObjectClouds:
        """`phrase` from the other view that sees most of it (every instance with `instances`); raises `hidden`,
        the observation camera's error, when no view sees it."""
        found = None
        for view in self.frames(step):
            try:
                seen = (self.observer.observe_instances(view, [phrase]) if instances
                        else self.observer.observe(view, [phrase]))
            except PerceptionError:
                continue
            if found is None or seen.point_counts.sum() > found.point_counts.sum():
                found = seen
        if found is None:
            raise hidden
        if phrase not in self.seen:
            self.seen.append(phrase)
        return found

    def observe_anywhere(self, frame: RGBDFrame, phrase: str, *, step: int, instances: bool = False) -> ObjectClouds:
        """`phrase` in `frame` (every instance with `instances`), else in the other view that sees most of it."""
        try:
            return (self.observer.observe_instances(frame, [phrase]) if instances
                    else self.observer.observe(frame, [phrase]))
        except PerceptionError as hidden:
            return self.observe(phrase, hidden, step=step, instances=instances)
