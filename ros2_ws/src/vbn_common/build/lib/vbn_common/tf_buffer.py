"""The transforms of a recorded ``/tf`` and ``/tf_static``, looked up at many stamps at once.

The exploration reader needs each image's ``map -> base_link`` chain and the
``base_link -> camera`` mount: :class:`TfBuffer` collects the links of both topics (a
newer static transform replaces an older one, as in tf2, and a replacement that moves
the child is recorded in :attr:`TfBuffer.static_changes` for the reader to report; a
child with two parents is a conflict reported by the reader) and
:meth:`TfBuffer.lookup` composes the chain from one frame to another at every stamp in
one vectorised pass, each dynamic link taken at its nearest sample within a tolerance
(no interpolation: an exploring robot stands still while it takes images). Messages are
duck-typed; no ROS type is imported.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vbn_common.errors import VbnCommonError

__all__ = ['TfBuffer', 'TfLink', 'compose_transforms', 'nearest_stamps', 'quaternion_matrices',
           'rotation_angles_deg']


# -- rigid transforms, vectorised --------------------------------------------------------
# geometry.frames holds the planar pose algebra; the tf chain needs full 3-D rotations
# (the optical camera frame is not a yaw rotation of base_link), stacked per image.
def rotation_angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the angle in degrees of the rotation from ``a`` to ``b``, ``(..., 3, 3)`` each.

    ``arccos((trace(a^T b) - 1) / 2)``, clipped; NaN where either holds a NaN.
    """
    cosine = (np.einsum('...ji,...ji->...', np.asarray(a, float), np.asarray(b, float))
              - 1.0) / 2.0
    with np.errstate(invalid='ignore'):
        return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """``(n, 4)`` quaternions ``(x, y, z, w)`` -> ``(n, 3, 3)`` rotations; zero -> NaN."""
    q = np.asarray(q, dtype=float).reshape(-1, 4)
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    with np.errstate(invalid='ignore', divide='ignore'):
        q = np.where(norm > 1e-12, q / norm, np.nan)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


def compose_transforms(outer: tuple[np.ndarray, np.ndarray],
             inner: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``outer (+) inner`` for stacks of rigid transforms ``(R (n,3,3), t (n,3))``."""
    r_out, t_out = outer
    r_in, t_in = inner
    return r_out @ r_in, np.einsum('nij,nj->ni', r_out, t_in) + t_out


def nearest_stamps(stamps: np.ndarray, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index into sorted ``stamps`` of the nearest stamp to each query, and the gap (ns)."""
    right = np.clip(np.searchsorted(stamps, queries), 0, len(stamps) - 1)
    left = np.clip(right - 1, 0, len(stamps) - 1)
    gap_left = np.abs(queries - stamps[left])
    gap_right = np.abs(stamps[right] - queries)
    index = np.where(gap_right < gap_left, right, left)
    return index, np.minimum(gap_left, gap_right)


@dataclass
class TfLink:
    """A ``/tf`` link ``parent -> child``: samples over time (static: one, no stamp)."""

    parent: str
    static: bool
    stamps: list[int] = field(default_factory=list)
    translations: list[tuple[float, float, float]] = field(default_factory=list)
    quaternions: list[tuple[float, float, float, float]] = field(default_factory=list)


class TfBuffer:
    """The links of ``/tf`` and ``/tf_static``, looked up at many stamps at once."""

    def __init__(self) -> None:
        self.links: dict[str, TfLink] = {}  # by child frame
        self.conflicts: set[str] = set()
        # Static links replaced by a different transform: child -> the largest change,
        # (rotation in degrees, translation in metres).
        self.static_changes: dict[str, tuple[float, float]] = {}

    def add(self, transform: Any, stamp_ns: int, static: bool) -> None:
        parent = str(transform.header.frame_id).lstrip('/')
        child = str(transform.child_frame_id).lstrip('/')
        link = self.links.get(child)
        if link is None or (static and not link.static):
            link = self.links[child] = TfLink(parent, static)
        elif link.parent != parent:
            self.conflicts.add(f'{child} (parents {link.parent} and {parent})')
            return
        elif static:  # a newer static transform replaces the older one
            self._note_static_change(child, link, transform)
            link.stamps.clear()
            link.translations.clear()
            link.quaternions.clear()
        elif link.static:
            return
        t, q = transform.transform.translation, transform.transform.rotation
        link.stamps.append(stamp_ns)
        link.translations.append((float(t.x), float(t.y), float(t.z)))
        link.quaternions.append((float(q.x), float(q.y), float(q.z), float(q.w)))

    def _note_static_change(self, child: str, link: TfLink, transform: Any) -> None:
        """Record how far a replacing static transform moves ``child`` (if at all)."""
        if not link.quaternions:
            return
        t, q = transform.transform.translation, transform.transform.rotation
        old, new = quaternion_matrices([link.quaternions[-1],
                                        (float(q.x), float(q.y), float(q.z), float(q.w))])
        angle = float(rotation_angles_deg(old, new))
        shift = float(np.linalg.norm(np.subtract((float(t.x), float(t.y), float(t.z)),
                                                 link.translations[-1])))
        if angle > 1e-6 or shift > 1e-9:
            before = self.static_changes.get(child, (0.0, 0.0))
            self.static_changes[child] = (max(before[0], angle), max(before[1], shift))

    def static_change_warnings(self, parent: str, child: str) -> list[str]:
        """Return one line per static link of the chain ``parent -> child`` that moved."""
        lines = []
        for frame in (self.chain(parent, child) or [])[:-1]:
            change = self.static_changes.get(frame)
            if change is not None:
                lines.append(f'the static transform {self.links[frame].parent} -> {frame} '
                             f'changes during the bag (by {change[0]:.2f} deg and '
                             f'{change[1]:.3f} m): every frame uses its last value (tf2 keeps '
                             'the newest static transform)')
        return lines

    def chain(self, parent: str, child: str) -> list[str] | None:
        """Return the frames from ``child`` up to ``parent`` (both included), or None."""
        frames = [child]
        while frames[-1] != parent:
            link = self.links.get(frames[-1])
            if link is None or link.parent in frames:
                return None
            frames.append(link.parent)
        return frames

    def lookup(self, parent: str, child: str, stamps: np.ndarray,
               tolerance_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Return ``(R (n,3,3), t (n,3), found (n,))`` of ``child`` in ``parent``, or None.

        ``found`` is False where a dynamic link has no sample within the tolerance.

        Raises:
            VbnCommonError: a dynamic link's stamps go back in time by more than
                :data:`MAX_BACK_NS` in the order they were recorded (an odometry reset, a
                rewound clock): samples sorted by stamp would interleave two histories.
        """
        frames = self.chain(parent, child)
        if frames is None:
            return None
        n = len(stamps)
        rotation = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        translation = np.zeros((n, 3))
        found = np.ones(n, dtype=bool)
        for frame in frames[:-1]:
            link = self.links[frame]
            if link.static:
                index = np.zeros(n, dtype=np.intp)
                link_rotation = quaternion_matrices(link.quaternions)[index]
                link_translation = np.asarray(link.translations, dtype=float)[index]
            else:
                link_stamps = np.asarray(link.stamps, dtype=np.int64)
                _refuse_jumps_back(link.parent, frame, link_stamps)
                order = np.argsort(link_stamps, kind='stable')
                index, gap = nearest_stamps(link_stamps[order], stamps)
                index = order[index]
                found &= gap <= tolerance_ns
                link_rotation = quaternion_matrices(np.asarray(link.quaternions)[index])
                link_translation = np.asarray(link.translations, dtype=float)[index]
            rotation, translation = compose_transforms((link_rotation, link_translation),
                                             (rotation, translation))
        return rotation, translation, found


#: Out-of-order /tf samples within this are delivery jitter; further back is a new history.
MAX_BACK_NS = 500_000_000


def _refuse_jumps_back(parent: str, child: str, stamps: np.ndarray) -> None:
    """Raise when ``stamps`` (in recorded order) go back by more than :data:`MAX_BACK_NS`."""
    if len(stamps) < 2:
        return
    back = stamps[:-1] - stamps[1:]              # a jump back from one sample to the next
    jumps = np.flatnonzero(back > MAX_BACK_NS)
    if len(jumps):
        k = int(jumps[0]) + 1
        raise VbnCommonError(
            f'/tf {parent} -> {child}: stamps go back by {back[k - 1] / 1e9:.2f} s at sample '
            f'{k} of {len(stamps)} ({len(jumps)} jump(s) back in all): the odometry was reset '
            'or the clock rewound; split the bag at the jump')
