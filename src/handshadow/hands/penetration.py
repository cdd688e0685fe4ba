"""Do the hands pass through each other? An exact test on the meshes, and a penalty from it.

A person's skin gives a little, so a vertex may sit up to TOLERANCE_MM inside other flesh; any
deeper and the pose cannot be held. Two tests, both on the closed meshes that are written as
``left.obj`` / ``right.obj`` (forearms included):

* **between the hands**: a vertex of one hand is inside the other hand's closed surface when
  its generalised winding number (Jacobson et al. 2013) with respect to that surface is over
  one half; its depth is its exact distance to that surface (to the nearest point of any
  triangle, not to the nearest vertex).
* **within a hand**: the hand is cut into closed parts (each finger, capped at its base, and
  the palm with the forearm, capped at the five finger bases). A finger's vertices are tested
  against every other finger, and its middle and end segments against the palm; neighbouring
  segments of one finger, and a finger's base against the palm it grows from, bend into each
  other at every joint crease and are not tested.

Winding numbers and distances come from libigl: the winding numbers from its fast (Barnes-Hut)
approximation, worked out exactly wherever that lands near one half (:func:`winding_inside`),
the distances exact and hierarchical. :func:`contact_penalty`
turns the contacts found into a differentiable cost, so an optimiser can push the hands apart
along the other surface's normal.
"""

from __future__ import annotations

import dataclasses
import functools

import igl
import numpy as np
import torch

from handshadow.hands.rig import boundary_loops

TOLERANCE_MM = 3.0  # what skin gives: deeper than this, the pose cannot be held
# winding_inside: fast winding numbers within this of one half are worked out exactly. The fast
# one strayed at most 0.005 from the exact on the 34,187 points of 47 recorded tests of fits.
WINDING_UNSURE = 0.25
HULL_PAD_M = 1e-6  # Hull's margin: a micrometre, far above rounding, far below any depth that counts
FINGER_BASE = 0  # segment index of a finger's base (MCP; the thumb's CMC)


@dataclasses.dataclass(frozen=True)
class Part:
    """A closed piece of one hand's mesh: faces (F, 3) into the hand's vertices, and the
    boundary loops (each an (L,) vertex index array, in order) that a fan from the loop's
    centre closes; vertices (N,) it owns, ascending (those its faces use)."""

    name: str
    faces: np.ndarray
    loops: tuple[np.ndarray, ...]
    vertices: np.ndarray

    def closed(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(vertices (N + C, 3), faces) of the part closed by its C caps, given the hand's
        posed vertices (V, 3): the part's own vertices in the order of ``vertices``, then the
        caps' centres; the faces (its own first, then the caps') index into them."""
        own = positions[self.vertices]
        local_loops, closed_faces = self._local
        centres = [own[loop].mean(0) for loop in local_loops]
        return np.concatenate([own, np.asarray(centres).reshape(-1, 3)]), closed_faces

    @functools.cached_property
    def _local(self) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """The loops and the closed faces in the part's own vertex order (closed())."""
        local = lambda idx: np.searchsorted(self.vertices, idx)  # noqa: E731
        loops = tuple(local(loop) for loop in self.loops)
        n = len(self.vertices)
        caps = [np.stack([loop, np.roll(loop, -1), np.full(len(loop), n + k)], 1) for k, loop in enumerate(loops)]
        return loops, np.concatenate([local(self.faces), *caps])


@dataclasses.dataclass(frozen=True)
class HandParts:
    """One hand mesh cut into closed parts: fingers[f] (thumb..little) and the palm (with the
    wrist and forearm); segment (V,) each vertex's finger segment 0..2, -1 on the palm."""

    fingers: tuple[Part, ...]
    palm: Part
    segment: np.ndarray


def split_hand(faces: np.ndarray, skin_weights: np.ndarray, joint_bones: np.ndarray) -> HandParts:
    """Cut a closed hand mesh into parts by each vertex's strongest bone: a triangle belongs to
    a finger when all three corners do, else to the palm. faces (F, 3), skin_weights (V, K),
    joint_bones (15,) the bone of each finger joint (thumb..little, base to tip)."""
    faces = np.asarray(faces, np.int64)
    owner = np.asarray(skin_weights).argmax(1)
    finger_of_bone = np.full(skin_weights.shape[1], -1)
    segment_of_bone = np.full(skin_weights.shape[1], -1)
    for j, b in enumerate(np.asarray(joint_bones)):
        finger_of_bone[b], segment_of_bone[b] = j // 3, j % 3
    finger = finger_of_bone[owner]
    corner = finger[faces]
    in_finger = (corner == corner[:, :1]).all(1) & (corner[:, 0] >= 0)
    fingers = []
    for f in range(5):
        sub = faces[in_finger & (corner[:, 0] == f)]
        fingers.append(Part(f"finger{f}", sub, tuple(boundary_loops(sub)), np.unique(sub)))
    palm_faces = faces[~in_finger]
    palm = Part("palm", palm_faces, tuple(boundary_loops(palm_faces)), np.unique(palm_faces))
    return HandParts(tuple(fingers), palm, segment_of_bone[owner])


@dataclasses.dataclass(frozen=True)
class Contacts:
    """Vertices found inside other flesh, N of them. For each: the hand it belongs to (mesh),
    its index there (vertex), the hand whose surface it is inside (other; the same hand for a
    finger inside another part), the nearest point of that surface as barycentric weights
    (bary (N, 3)) on three of the other hand's vertices (corners (N, 3)), the surface's
    outward normal there when found (normal (N, 3)) and the depth, metres; item: which pose of
    a batch. The nearest point is on the skin: a part's caps decide what is inside only."""

    item: np.ndarray
    mesh: np.ndarray
    vertex: np.ndarray
    other: np.ndarray
    corners: np.ndarray
    bary: np.ndarray
    normal: np.ndarray
    depth_m: np.ndarray

    @staticmethod
    def empty() -> Contacts:
        z = np.zeros(0, np.int64)
        return Contacts(z, z, z, z, np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    def for_item(self, item: int) -> Contacts:
        """The same contacts as those of pose ``item`` of a batch."""
        return dataclasses.replace(self, item=np.full(len(self.item), item))

    @staticmethod
    def cat(items: list[Contacts]) -> Contacts:
        if not items:
            return Contacts.empty()
        return Contacts(*(np.concatenate([getattr(c, f.name) for c in items]) for f in dataclasses.fields(Contacts)))


@dataclasses.dataclass(frozen=True)
class Penetration:
    """The exact test's answer for one pose: the deepest vertex between the hands and within
    each hand, millimetres (0 when none is inside), and every contact deeper than
    ``report_mm``."""

    between_mm: float
    within_mm: tuple[float, ...]
    contacts: Contacts

    @property
    def deepest_mm(self) -> float:
        return max([self.between_mm, *self.within_mm])

    def performable(self, tolerance_mm: float = TOLERANCE_MM) -> bool:
        return self.deepest_mm <= tolerance_mm


def penetration(
    positions: list[np.ndarray], faces: list[np.ndarray], parts: list[HandParts] | None = None, report_mm: float = 0.0
) -> Penetration:
    """The exact test for one pose of one or two hands.

    Args:
        positions: per hand its posed vertices (V_i, 3), metres.
        faces: per hand its closed mesh's faces (F_i, 3).
        parts: per hand its split (:func:`split_hand`), for the test within each hand; None
            skips that test.
        report_mm: contacts at least this deep are listed (all inside vertices by default).
    """
    found, between = [], 0.0
    if len(positions) == 2:
        for a, b in ((0, 1), (1, 0)):
            hull = Hull.of(positions[b])
            (c,) = _inside(positions[a], [np.arange(len(positions[a]))], positions[b], faces[b], a, b, report_mm, hull)
            between = max(between, float(c.depth_m.max(initial=0.0)) * 1000)
            found.append(c)
    within = []
    for h, split in enumerate(parts or []):
        closed = {part.name: part.closed(positions[h]) for part in (*split.fingers, split.palm)}
        pairs = list(_part_pairs(split))
        results: list[Contacts] = [Contacts.empty()] * len(pairs)
        # One pass per part over every query of it (one tree per part), kept in the pairs' order.
        for target in (*split.fingers, split.palm):
            which = [i for i, (t, _) in enumerate(pairs) if t is target]
            verts, tri = closed[target.name]
            groups = [pairs[i][1] for i in which]
            hull = Hull.of(verts)
            for i, c in zip(which, _inside(positions[h], groups, verts, tri, h, h, report_mm, hull, target)):
                results[i] = c
        within.append(max(float(c.depth_m.max(initial=0.0)) for c in results) * 1000)
        found.extend(results)
    return Penetration(between, tuple(within), Contacts.cat(found))


@dataclasses.dataclass(frozen=True)
class Hull:
    """A box that holds a surface, along the principal axes of its points: no point outside it
    can be inside the surface, so the winding numbers are worked out for the points in it only.
    A finger lying across the frame's axes fills a fraction of its axis-aligned box. The box
    is HULL_PAD_M larger each way, so that rounding in its turned frame loses no point of the
    surface itself."""

    centre: np.ndarray  # (3,)
    axes: np.ndarray  # (3, 3), one axis per column
    lo: np.ndarray  # (3,) the box's extent along each axis from the centre
    hi: np.ndarray

    @staticmethod
    def of(points: np.ndarray) -> Hull:
        """The box of points (N, 3)."""
        centre = points.mean(0)
        _, axes = np.linalg.eigh(np.cov((points - centre).T))
        local = (points - centre) @ axes
        return Hull(centre, axes, local.min(0) - HULL_PAD_M, local.max(0) + HULL_PAD_M)

    def holds(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which points (N, 3) lie in the box."""
        local = (points - self.centre) @ self.axes
        return np.all((local >= self.lo) & (local <= self.hi), 1)


def _part_pairs(split: HandParts):
    """(closed part, query vertex indices) pairs of the test within a hand."""
    for f, part in enumerate(split.fingers):
        for g, other in enumerate(split.fingers):
            if g != f:
                yield other, part.vertices
        beyond_base = part.vertices[split.segment[part.vertices] > FINGER_BASE]
        yield split.palm, beyond_base


def _inside(query_pos, groups, verts, tri, mesh, other, report_mm, hull: Hull, part: Part | None = None) -> list:
    """Per group of query vertices (each an index array into query_pos), its Contacts inside
    the closed (verts, tri), whose points the hull holds; the groups are tested together, each
    point on its own. With ``part`` (verts, tri are its closed(): its own vertices, then its
    caps' centres) the nearest point is sought on its skin, not its caps, and the corners are
    given as the hand's vertex indices."""
    query_idx = np.concatenate(groups)
    group = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    pts = query_pos[query_idx]
    near = hull.holds(pts)  # only points in the surface's box can be inside
    if not near.any():
        return [Contacts.empty()] * len(groups)
    idx, group, pts = query_idx[near], group[near], pts[near]
    inside = winding_inside(verts, tri, pts)
    if not inside.any():
        return [Contacts.empty()] * len(groups)
    idx, group, pts = idx[inside], group[inside], pts[inside]
    skin = tri if part is None else tri[: len(part.faces)]
    sq, tid, closest = igl.point_mesh_squared_distance(pts, verts, skin)
    depth = np.sqrt(sq)
    keep = depth * 1000 >= report_mm
    idx, group, tid, closest, depth = idx[keep], group[keep], tid[keep], closest[keep], depth[keep]
    corners = skin[tid]
    a, b, c = verts[corners[:, 0]], verts[corners[:, 1]], verts[corners[:, 2]]
    bary = _barycentric(closest, a, b, c)
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    if part is not None:
        corners = part.vertices[corners]
    out = []
    for g in range(len(groups)):
        sel = group == g
        n = int(sel.sum())
        out.append(
            Contacts(
                np.zeros(n, np.int64),
                np.full(n, mesh),
                idx[sel],
                np.full(n, other),
                corners[sel],
                bary[sel],
                normal[sel],
                depth[sel],
            )
        )
    return out


def winding_inside(verts: np.ndarray, tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: which points (N, 3) lie inside the closed surface (verts (V, 3), tri (F, 3)):
    generalised winding number over one half. libigl's fast winding number (a tree of
    far-field expansions) decides every point whose value lies more than WINDING_UNSURE from
    one half, the exact sum over all triangles the rest. That is the exact test's answer
    wherever the fast value strays less than WINDING_UNSURE (on recorded fits it strayed at
    most 0.005), about twice as fast on a hand's vertices."""
    w = igl.fast_winding_number(verts, tri, points)
    unsure = np.abs(w - 0.5) < WINDING_UNSURE
    if unsure.any():
        w[unsure] = igl.winding_number(verts, tri, points[unsure])
    return w > 0.5


def _barycentric(p, a, b, c) -> np.ndarray:
    """(N, 3) barycentric coordinates of points p (N, 3) on triangles (a, b, c)."""
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.where(np.abs(d00 * d11 - d01 * d01) > 1e-30, d00 * d11 - d01 * d01, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - v - w, v, w], 1)


def contact_penalty(
    vertices: list[torch.Tensor],
    contacts: Contacts,
    margin_m: float = 0.001,
    light: torch.Tensor | None = None,
    sideways: float = 1.0,
) -> torch.Tensor:
    """A differentiable cost of contacts: per pose of a batch, the sum of squared depths (in
    centimetres, plus ``margin_m`` so that they end just apart) of each contact vertex behind
    the nearest point of the other surface, along that surface's normal.

    vertices: per hand its posed vertices (B, V_i, 3); contacts.item says which pose each
    contact belongs to. With ``light`` (a point light's position (3,)) the push between the
    two hands keeps only ``sideways`` of its gradient across the light's ray: moving a hand
    along its rays keeps its shadow in place. -> (B,)."""
    batch, dev = vertices[0].shape[0], vertices[0].device
    total = vertices[0].new_zeros(batch)
    for a in range(len(vertices)):
        for b in range(len(vertices)):
            sel = (contacts.mesh == a) & (contacts.other == b)
            if not sel.any():
                continue
            item = torch.as_tensor(contacts.item[sel], device=dev)
            p = vertices[a][item, torch.as_tensor(contacts.vertex[sel], device=dev)]  # (N, 3)
            corners = torch.as_tensor(contacts.corners[sel], device=dev)
            tri = vertices[b][item[:, None], corners]  # (N, 3 corners, 3)
            bary = torch.as_tensor(contacts.bary[sel], dtype=p.dtype, device=dev)
            with torch.no_grad():  # the surface's normal now (it turns with its hand)
                normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                normal = normal / normal.norm(dim=-1, keepdim=True).clamp(min=1e-12)
            e = (tri * bary[..., None]).sum(1) - p  # to the surface point: along the normal when inside
            if light is not None and a != b and sideways < 1.0:
                with torch.no_grad():
                    ray = p - light
                    ray = ray / ray.norm(dim=-1, keepdim=True).clamp(min=1e-12)
                along = (e * ray).sum(-1, keepdim=True) * ray
                side = e - along
                e = along + sideways * side + (1 - sideways) * side.detach()
            depth = (e * normal).sum(-1) + margin_m
            total = total.index_add(0, item, (torch.relu(depth) / 0.01) ** 2)
    return total


def hand_parts(model) -> HandParts:
    """The split of a HandModel's mesh (cached per model)."""
    cached = getattr(model, "_parts", None)
    if cached is None:
        cached = split_hand(
            model.faces.cpu().numpy(), model.skin_weights.cpu().numpy(), model.joint_bones.cpu().numpy()
        )
        model._parts = cached
    return cached
