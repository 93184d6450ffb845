"""Scene objects: what every object in the tabletop exposes, and the shared colour palette.

Every object added to a scene is described by an `ObjectInfo`: a unique scene `name`
("bowl", "red_bowl", "distractor_mug_0"), its `kind` ("bowl"), `color` word and `size` word,
the MuJoCo bodies whose pixels belong to it (segmentation is body-level) and a footprint
radius on the table used when placing other objects around it. Object builders
(`primitives.py`, `articulated.py`) take a `SceneBuilder`, add bodies to `builder.spec`
and register the object with `builder.register(info)`; they return the `ObjectInfo`.

Naming rule for bodies: every body of object `name` is called `name` or `name/<part>`,
so a body name maps back to its object by the text before the first "/".
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Named colours (RGBA, 0..1). Names are the words the language layer and the ground-truth
# segmenter match ("the red bowl"), so keep them common colour words.
PALETTE: dict[str, tuple[float, float, float, float]] = {
    "red": (0.85, 0.12, 0.10, 1.0),
    "green": (0.15, 0.65, 0.20, 1.0),
    "blue": (0.15, 0.30, 0.85, 1.0),
    "yellow": (0.95, 0.85, 0.15, 1.0),
    "orange": (0.95, 0.50, 0.10, 1.0),
    "purple": (0.55, 0.20, 0.70, 1.0),
    "pink": (0.95, 0.55, 0.70, 1.0),
    "cyan": (0.15, 0.80, 0.85, 1.0),
    "white": (0.92, 0.92, 0.90, 1.0),
    "black": (0.10, 0.10, 0.10, 1.0),
    "grey": (0.50, 0.50, 0.52, 1.0),
    "brown": (0.50, 0.32, 0.18, 1.0),
}

SIZE_WORDS = ("small", "medium", "large")


def rgba(color: str) -> list[float]:
    """RGBA list of a palette colour; raises KeyError naming the known colours."""
    if color not in PALETTE:
        raise KeyError(f"unknown colour {color!r}; known colours: {sorted(PALETTE)}")
    return list(PALETTE[color])


def size_word(scale: float) -> str:
    """Size word for a scale factor relative to the task's nominal object (1.0 = "medium")."""
    if scale < 0.9:
        return "small"
    if scale > 1.1:
        return "large"
    return "medium"


@dataclass
class ObjectInfo:
    """One object in a built scene.

    Attributes:
        name: unique scene name; also the key in `RGBDFrame.instance_names`.
        kind: category word ("bowl", "pan", "bottle", "drawer", "cylinder" for obstacles, ...).
        color: palette colour word.
        size: "small" | "medium" | "large".
        body_names: MuJoCo bodies that make up the object (segmentation is body-level).
        footprint_radius: radius of a disc on the table that contains the object, metres.
        position: nominal (x, y, z) where it was placed, metres, world frame.
        role: "target" (a task slot), "item" (other task object), "distractor", "similar", "obstacle".
        extents: (3,) half-extents of an axis-aligned box around the object in its own frame, metres;
            used by tests and obstacle costs.
    """

    name: str
    kind: str
    color: str
    size: str = "medium"
    body_names: tuple[str, ...] = ()
    footprint_radius: float = 0.05
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    role: str = "target"
    extents: np.ndarray = field(default_factory=lambda: np.full(3, 0.05))

    def attributes(self) -> dict[str, str]:
        """The descriptive words the ground-truth segmenter matches: kind, color, size (and role)."""
        return {"kind": self.kind, "color": self.color, "size": self.size, "role": self.role}


def object_of_body(body_name: str) -> str:
    """Object name of a body name under the "name/part" rule."""
    return body_name.split("/", 1)[0]


__all__ = ["PALETTE", "SIZE_WORDS", "ObjectInfo", "object_of_body", "rgba", "size_word"]
