"""World files: a Mitsuba world (shape and material) described in TOML, read and checked.

A world file holds ``name``, ``description``, a ``[shape]`` table and a ``[material]`` table::

    name = "copper-bowl"
    description = "rough copper (Cu, GGX alpha 0.3) on the bowl: a coloured metal's cavity"

    [shape]
    type = "bowl"          # torus-knot | bowl | relief | sphere | mesh
    radius = 0.85          # any parameter of the shape; the others keep their defaults

    [material]             # a Mitsuba BSDF dictionary (sim.world_materials)
    type = "roughconductor"
    material = "Cu"
    distribution = "ggx"
    alpha = 0.3

Shapes and their parameters are those of :mod:`sim.world_shapes` (``type = "mesh"`` takes
``file``, a PLY path relative to the world file, and ``scale``). Every world must fit inside the
unit sphere about the origin (the rig's cameras sit at distance ~4 with a 40-degree field of
view). Loading checks everything a render would trip on, so a bad file fails at once with its
path and key: TOML syntax, unknown keys, parameter types and ranges, the shape's size, textures
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

from core.errors import InputError
from sim.mitsuba_reference import DEFAULT_VARIANT, load_mitsuba
from sim.world_materials import instantiate_bsdf, material_dict, material_files, needs_uv
from sim.world_mesh import TriangleMesh, mitsuba_mesh, read_mesh_file
from sim.world_shapes import bowl_mesh, relief_mesh, sphere_mesh, torus_knot_mesh

__all__ = ["SHAPES", "WORLDS", "WORLDS_FOLDER", "World", "load_world"]

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
}  # fmt: skip
_MESH_KEYS = {"type", "file", "scale"}
_TOP_KEYS = {"name", "description", "shape", "material"}


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
    mesh : TriangleMesh, the shape built (the triangles Mitsuba renders and samples lie on)
    """

    name: str
    description: str
    source: Path
    text: str
    shape: dict[str, Any]
    material: dict[str, Any]
    digest: str
    mesh: TriangleMesh = field(repr=False, compare=False)

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
        return mitsuba_mesh(mi, self.mesh, bsdf, name=self.name)

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
        }


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
    """Build the ``[shape]`` table's mesh; also returns the files it read."""
    kind = table.get("type")
    if kind == "mesh":
        unknown = sorted(set(table) - _MESH_KEYS)
        if unknown:
            raise InputError(f"{where}: unknown key {unknown[0]!r} for a mesh; use file, scale")
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
                f"{where} {key}: unknown parameter of a {kind}; its parameters: {', '.join(spans)}"
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
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"{source}: unknown key {unknown[0]!r}; a world has {sorted(_TOP_KEYS)}")
    name, description = _text(data, "name", str(source)), _text(data, "description", str(source))
    for table in ("shape", "material"):
        if not isinstance(data.get(table), dict):
            raise InputError(f"{source}: needs a [{table}] table")
    mesh, shape_files = _shape(data["shape"], f"{source}: [shape]", source.parent)
    if mesh.bounding_radius > 1.0 + 1e-9:
        raise InputError(
            f"{source}: [shape] reaches {mesh.bounding_radius:.3f} from the origin; a world must "
            "fit inside the unit sphere (cameras at distance ~4, fov 40): make it smaller"
        )
    if mesh.uv is None and needs_uv(data["material"]):
        raise InputError(
            f"{source}: [material] uses textures or anisotropic roughness, which need texture "
            f"coordinates, and the [shape] mesh has none"
        )
    digest = hashlib.sha256(raw)
    for file in [*shape_files, *material_files(data["material"], source.parent)]:
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
        mesh=mesh,
    )
    mi = load_mitsuba(variant)
    instantiate_bsdf(mi, world.bsdf_dict(mi), f"{source}: [material]")
    return world
