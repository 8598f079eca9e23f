"""World files: a Mitsuba world (shape and material) described in TOML, read and checked.

A world file holds ``name``, ``description``, a ``[shape]`` table and a ``[material]`` table::

    name = "copper-bowl"
    description = "rough copper (Cu, GGX alpha 0.3) on the bowl: a coloured metal's cavity"

    [shape]
    type = "bowl"          # torus-knot | bowl | relief | sphere | mesh
    radius = 0.85          # any parameter of the shape; the others keep their defaults

    [material]             # a Mitsuba BSDF dictionary (sim.world.materials)
    type = "roughconductor"
    material = "Cu"
    distribution = "ggx"
    alpha = 0.3

Shapes and their parameters are those of :mod:`sim.world.shapes` (``type = "mesh"`` takes
``file``, a PLY path relative to the world file, and ``scale``); any shape also takes
``position = [x, y, z]``, where its centre goes (default the origin). Every object must fit
inside the unit sphere about the origin (the rig's cameras sit at distance ~4 with a 40-degree
field of view).

A scene of several objects on a base (optional; a world without them is one object as above)::

    [[objects]]            # more objects, each with its own shape and material
    shape = { type = "sphere", radius = 0.2, position = [0.0, 0.0, -0.1] }
    material = { type = "diffuse", reflectance = [0.8, 0.4, 0.1] }

    [base]                 # a square plate under the objects, facing +z
    size = 4.0             # its side (default 4; it may reach beyond the unit sphere)
    z = -0.4               # its height (default: the objects' lowest point, so they stand on it)
    material = { type = "diffuse", reflectance = [0.5, 0.5, 0.5] }   # (the default)

The world's :attr:`World.mesh` is then every part joined (its surface samples lie on the base
too), and :meth:`World.mitsuba_shapes` gives each part with its own material.

Loading checks everything a render would trip on, so a bad file fails at once with its path and
key: TOML syntax, unknown keys, parameter types and ranges, the shape's size, textures
on a mesh without uv, and the material itself, which Mitsuba instantiates.

The bundled worlds are the files in ``sim/worlds/`` (:data:`WORLDS`); ``docs/world.md`` says
what each one is for.
"""

from __future__ import annotations

import hashlib
import inspect
import os
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError
from sim.mitsuba_reference import DEFAULT_VARIANT, load_mitsuba
from sim.world.materials import instantiate_bsdf, material_dict, material_files, needs_uv
from sim.world.mesh import TriangleMesh, mitsuba_mesh, read_mesh_file
from sim.world.shapes import (
    bowl_mesh,
    cylinder_mesh,
    join_meshes,
    relief_mesh,
    sphere_mesh,
    torus_knot_mesh,
)

__all__ = ["SHAPES", "WORLDS", "WORLDS_FOLDER", "World", "WorldPart", "load_world"]

#: The folder of the bundled world files.
WORLDS_FOLDER = Path(str(resources.files("sim") / "worlds"))
#: The bundled worlds' names (their file names without ``.toml``).
WORLDS: tuple[str, ...] = tuple(sorted(path.stem for path in WORLDS_FOLDER.glob("*.toml")))

#: Each built-in shape's builder and its parameters' accepted ranges (inclusive); defaults are
#: the builder's own.
SHAPES: dict[str, tuple[Callable[..., TriangleMesh], dict[str, tuple[float, float]]]] = {
    "torus-knot": (torus_knot_mesh, {
        "p": (1, 20), "q": (1, 20), "major_radius": (0.01, 1.0), "knot_radius": (0.0, 1.0),
        "tube_radius": (0.005, 0.5), "curve_segments": (16, 20_000), "tube_segments": (3, 1024),
        "uv_repeats": (1, 1000),
    }),
    "bowl": (bowl_mesh, {
        "radius": (0.01, 1.0), "thickness": (0.001, 1.0), "rings": (2, 4096),
        "rim_segments": (2, 1024), "segments": (3, 4096),
    }),
    "relief": (relief_mesh, {
        "size": (0.01, 1.5), "height": (0.0, 1.0), "base": (0.001, 1.0),
        "resolution": (3, 2048), "seed": (0, 2**32 - 1),
    }),
    "sphere": (sphere_mesh, {"radius": (0.01, 1.0), "rings": (2, 4096), "segments": (3, 8192)}),
    "cylinder": (cylinder_mesh, {
        "radius": (0.01, 1.0), "height": (0.01, 2.0), "rings": (1, 4096), "segments": (3, 8192),
    }),
}  # fmt: skip
_MESH_KEYS = {"type", "file", "scale", "position"}
_TOP_KEYS = {"name", "description", "shape", "material", "objects", "base"}
_OBJECT_KEYS = {"shape", "material"}
_BASE_KEYS = {"size", "z", "material"}
#: The base's side when not given, and the largest accepted: it fills an overhead view of the
#: unit sphere (half width 1.15 at distance 4, fov 32) and keeps most grazing directions off
#: the floor below it.
BASE_SIZE = 4.0
MAX_BASE_SIZE = 8.0
#: The base's material when not given: a mid-grey Lambertian plate.
BASE_MATERIAL: dict[str, Any] = {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}


@dataclass(frozen=True, eq=False)
class WorldPart:
    """One part of a world: an object (or the base) with its own material.

    Attributes
    ----------
    label : str, names the part in messages and in Mitsuba (``object``, ``object-1``, ``base``)
    where : str, the file and table it came from, for messages
    material : dict, its material table as written
    mesh : TriangleMesh, placed (its ``position`` applied)
    """

    label: str
    where: str
    material: dict[str, Any]
    mesh: TriangleMesh


@dataclass(frozen=True)
class World:
    """A world read from its file: what it is, its mesh and its material.

    Attributes
    ----------
    name : str, the file's ``name``
    description : str, one line on what the world is for
    source : Path, the world file
    text : str, the file's text as read (recorded in the provenance of what is rendered)
    shape : dict, the ``[shape]`` table as written
    material : dict, the ``[material]`` table as written
    digest : str, SHA-256 (hex) of the file's text and of every file it names (mesh, images)
    mesh : TriangleMesh, the shape built (the triangles Mitsuba renders and samples lie on);
        with ``[[objects]]`` or a ``[base]``, every part joined
    parts : tuple of WorldPart, the ``[shape]`` object, then ``[[objects]]``, then the base
    base_z : float or None, the height of the base's top face (None: no base)
    """

    name: str
    description: str
    source: Path
    text: str
    shape: dict[str, Any]
    material: dict[str, Any]
    digest: str
    mesh: TriangleMesh = field(repr=False, compare=False)
    parts: tuple[WorldPart, ...] = field(default=(), repr=False, compare=False)
    base_z: float | None = None

    def bsdf_dict(self, mi: Any) -> dict[str, Any]:
        """The material as a Mitsuba BSDF dictionary (textures as in-memory bitmaps).

        Parameters
        ----------
        mi : the ``mitsuba`` module with a variant set
        """
        return material_dict(
            mi, self.material, where=f"{self.source}: [material]", folder=self.source.parent
        )

    def mitsuba_mesh(self, mi: Any) -> Any:
        """The world's object for a Mitsuba scene: an ``mi.Mesh`` carrying its BSDF.

        Parameters
        ----------
        mi : the ``mitsuba`` module with a variant set

        Raises
        ------
        InputError
            Mitsuba refuses the material (named with the file).
        """
        bsdf = instantiate_bsdf(mi, self.bsdf_dict(mi), f"{self.source}: [material]")
        mesh = self.parts[0].mesh if self.parts else self.mesh
        return mitsuba_mesh(mi, mesh, bsdf, name=self.name)

    def mitsuba_shapes(self, mi: Any) -> dict[str, Any]:
        """Every part as an ``mi.Mesh`` with its BSDF, keyed for a Mitsuba scene dictionary.

        A one-object world gives ``{"object": ...}`` (:meth:`mitsuba_mesh`); more objects add
        ``object-1``, ... and a base adds ``base``.

        Parameters
        ----------
        mi : the ``mitsuba`` module with a variant set
        """
        if len(self.parts) <= 1:
            return {"object": self.mitsuba_mesh(mi)}
        shapes = {}
        for part in self.parts:
            table = material_dict(mi, part.material, where=part.where, folder=self.source.parent)
            bsdf = instantiate_bsdf(mi, table, part.where)
            shapes[part.label] = mitsuba_mesh(mi, part.mesh, bsdf, name=f"{self.name}.{part.label}")
        return shapes

    def to_json(self) -> dict[str, Any]:
        """The world as plain JSON: name, description, file, digest, shape, material, text."""
        return {
            "name": self.name,
            "description": self.description,
            "file": str(self.source),
            "digest": self.digest,
            "shape": self.shape,
            "material": self.material,
            "text": self.text,
        } | ({"parts": [part.label for part in self.parts]} if len(self.parts) > 1 else {})


def _parameter(value: Any, default: Any, span: tuple[float, float], where: str) -> Any:
    low, high = span
    whole = isinstance(default, int)
    ok_type = not isinstance(value, bool) and (
        isinstance(value, int) if whole else isinstance(value, int | float)
    )
    if not ok_type or not low <= value <= high:
        kind = "a whole number" if whole else "a number"
        raise InputError(f"{where}: expected {kind} in [{low:g}, {high:g}], got {value!r}")
    return value


def _shape(table: Mapping[str, Any], where: str, folder: Path) -> tuple[TriangleMesh, list[Path]]:
    """Build the ``[shape]`` table's mesh, placed; also returns the files it read."""
    table = dict(table)
    position = table.pop("position", None)
    mesh, files = _unplaced_shape(table, where, folder)
    if position is None:
        return mesh, files
    if (
        not isinstance(position, list)
        or len(position) != 3
        or not all(
            isinstance(c, int | float) and not isinstance(c, bool) and abs(c) <= 1.0
            for c in position
        )
    ):
        raise InputError(f"{where} position: expected [x, y, z] within [-1, 1], got {position!r}")
    offset = np.asarray(position, dtype=np.float64)
    return TriangleMesh(mesh.vertices + offset, mesh.faces, mesh.normals, mesh.uv), files


def _unplaced_shape(
    table: Mapping[str, Any], where: str, folder: Path
) -> tuple[TriangleMesh, list[Path]]:
    kind = table.get("type")
    if kind == "mesh":
        unknown = sorted(set(table) - _MESH_KEYS)
        if unknown:
            raise InputError(
                f"{where}: unknown key {unknown[0]!r} for a mesh; use file, scale, position"
            )
        if not isinstance(table.get("file"), str):
            raise InputError(f'{where}: a mesh needs file = "name.ply" (relative to the world)')
        file = folder / table["file"]
        scale = _parameter(table.get("scale", 1.0), 1.0, (1e-6, 1e6), f"{where} scale")
        return read_mesh_file(file, scale=scale), [file]
    if kind not in SHAPES:
        raise InputError(
            f"{where} type: unknown shape {kind!r}; known shapes: {', '.join([*SHAPES, 'mesh'])}"
        )
    builder, spans = SHAPES[kind]
    defaults = {
        name: parameter.default for name, parameter in inspect.signature(builder).parameters.items()
    }
    values: dict[str, Any] = {}
    for key, value in table.items():
        if key == "type":
            continue
        if key not in spans:
            raise InputError(
                f"{where} {key}: unknown parameter of a {kind}; its parameters: "
                f"{', '.join([*spans, 'position'])}"
            )
        values[key] = _parameter(value, defaults[key], spans[key], f"{where} {key}")
    try:
        return builder(**values), []
    except InputError as error:  # a combination of parameters the builder refuses
        raise InputError(f"{where}: {error}") from error


def _text(table: Mapping[str, Any], key: str, where: str) -> str:
    value = table.get(key)
    if not isinstance(value, str) or not value.strip():
        raise InputError(f'{where}: needs {key} = "..." (a non-empty string)')
    return value


def _world_file(path_or_name: str | os.PathLike[str]) -> Path:
    text = os.fspath(path_or_name)
    if isinstance(path_or_name, os.PathLike) or text.endswith(".toml") or os.sep in text:
        return Path(text)
    if text not in WORLDS:
        raise InputError(
            f"unknown world {text!r}; the bundled worlds are {', '.join(WORLDS)} "
            "(or give the path of a .toml world file)"
        )
    return WORLDS_FOLDER / f"{text}.toml"


def load_world(path_or_name: str | os.PathLike[str], *, variant: str = DEFAULT_VARIANT) -> World:
    """Read and check a world file; a bare name is a bundled world (:data:`WORLDS`).

    Parameters
    ----------
    path_or_name : a world file's path, or a bundled world's name
    variant : the Mitsuba variant the material is checked in

    Returns
    -------
    World

    Raises
    ------
    InputError
        An unknown name, a missing or unreadable file, invalid TOML, or a key or value the
        file should not have (see the module docstring); the message names the file and key.
    MitsubaUnavailableError
        Mitsuba 3 is not installed (the material is checked by instantiating it).
    """
    source = _world_file(path_or_name)
    try:
        raw = source.read_bytes()
        text = raw.decode("utf-8")
        data = tomllib.loads(text)
    except OSError as error:
        raise InputError(
            f"{source}: cannot read the world file ({error.strerror or error})"
        ) from error
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise InputError(f"{source}: not a valid TOML world file: {error}") from error
    except RecursionError:  # arrays nested thousands deep
        raise InputError(f"{source}: the world file is nested too deeply to read") from None
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"{source}: unknown key {unknown[0]!r}; a world has {sorted(_TOP_KEYS)}")
    name, description = _text(data, "name", str(source)), _text(data, "description", str(source))
    for table in ("shape", "material"):
        if not isinstance(data.get(table), dict):
            raise InputError(f"{source}: needs a [{table}] table")
    tables = [("object", f"{source}: [shape]", data["shape"], f"{source}: [material]",
               data["material"])]  # fmt: skip
    objects = data.get("objects", [])
    if not isinstance(objects, list) or not all(isinstance(o, dict) for o in objects):
        raise InputError(f"{source}: objects must be [[objects]] tables (shape and material)")
    for k, table in enumerate(objects, start=1):
        where = f"{source}: objects[{k}]"
        unknown = sorted(set(table) - _OBJECT_KEYS)
        if unknown:
            raise InputError(f"{where}: unknown key {unknown[0]!r}; an object has shape, material")
        for key in ("shape", "material"):
            if not isinstance(table.get(key), dict):
                raise InputError(f"{where}: needs a {key} table")
        tables.append((f"object-{k}", f"{where}.shape", table["shape"], f"{where}.material",
                       table["material"]))  # fmt: skip
    parts, files = [], []
    for label, shape_where, shape, material_where, material in tables:
        mesh, shape_files = _shape(shape, shape_where, source.parent)
        if mesh.bounding_radius > 1.0 + 1e-9:
            raise InputError(
                f"{shape_where} reaches {mesh.bounding_radius:.3f} from the origin; a world must "
                "fit inside the unit sphere (cameras at distance ~4, fov 40): make it smaller"
            )
        if mesh.uv is None and needs_uv(material):
            raise InputError(
                f"{material_where} uses textures or anisotropic roughness, which need texture "
                f"coordinates, and the {'[shape]' if label == 'object' else 'shape'} mesh has none"
            )
        parts.append(WorldPart(label, material_where, dict(material), mesh))
        files += [*shape_files, *material_files(material, source.parent)]
    base_z = None
    if "base" in data:
        base, base_z = _base(data["base"], f"{source}: [base]", parts)
        parts.append(base)
        files += material_files(base.material, source.parent)
    digest = hashlib.sha256(raw)
    for file in files:
        if file.is_file():  # a missing image is reported below, by the material check
            digest.update(file.read_bytes())
    world = World(
        name=name,
        description=description,
        source=source,
        text=text,
        shape=dict(data["shape"]),
        material=dict(data["material"]),
        digest=digest.hexdigest(),
        mesh=join_meshes([part.mesh for part in parts]),
        parts=tuple(parts),
        base_z=base_z,
    )
    mi = load_mitsuba(variant)
    for part in parts:
        bsdf = material_dict(mi, part.material, where=part.where, folder=source.parent)
        instantiate_bsdf(mi, bsdf, part.where)
    return world


def _base(table: Any, where: str, objects: list[WorldPart]) -> tuple[WorldPart, float]:
    """The ``[base]`` plate (two triangles facing +z, uv over [0, 1]^2) and its height."""
    if not isinstance(table, dict):
        raise InputError(f"{where}: must be a table (size, z, material)")
    unknown = sorted(set(table) - _BASE_KEYS)
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r}; a base has {sorted(_BASE_KEYS)}")
    size = _parameter(table.get("size", BASE_SIZE), BASE_SIZE, (0.01, MAX_BASE_SIZE),
                      f"{where} size")  # fmt: skip
    lowest = min(float(part.mesh.vertices[:, 2].min()) for part in objects)
    z = _parameter(table.get("z", lowest), 0.0, (-1.0, 1.0), f"{where} z")
    material = table.get("material", BASE_MATERIAL)
    if not isinstance(material, dict):
        raise InputError(f"{where} material: expected a table (a Mitsuba BSDF)")
    half = 0.5 * size
    corners = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    plate = TriangleMesh(
        corners,
        np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64),
        np.tile([0.0, 0.0, 1.0], (4, 1)),
        np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
    )
    return WorldPart("base", f"{where} material", dict(material), plate), float(z)
