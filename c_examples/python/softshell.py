"""softshell from Python: a ctypes binding of the C ABI in include/softshell.h.

Arrays go in and come out as numpy arrays (positions as (n, 3) float32, triangles as (m, 3)
uint32); every failing call raises ``softshell.Error`` carrying the status name and the library's
message. Handles (``Mesh``, ``Shell``, ``Body``, ``Lattice``) free their library object when
closed, when used as a context manager, or when garbage-collected.

The library is found through the ``SOFTSHELL_LIBRARY`` environment variable (a path to
libsoftshell.so / .dylib / softshell.dll), then ``$CARGO_TARGET_DIR/release``, then the
repository's ``target/release``, then the system's library path.

Defs are the C structs (``ShellDef``...), filled with the library's defaults by ``shell_def()``
and friends; constructors also take field overrides as keyword arguments::

    import softshell
    mesh = softshell.Mesh.load_obj("data/sphere.obj")
    shell = softshell.Shell(mesh, pressure=0.5, stop_volume_ratio=0.6)
    while not shell.step().finished:
        pass
    print(shell.positions().shape)
"""

import ctypes
import ctypes.util
import os
import sys

import numpy as np

__all__ = [
    "Error", "Mesh", "Shell", "Body", "Lattice", "ccd_vertex_triangle", "ccd_edge_edge",
    "shell_def", "anisotropy_def", "body_def", "lattice_def", "version", "library_path",
]

# ---------------------------------------------------------------------------------------------
# Constants (the #defines of softshell.h; test_binding.py checks them against the header).

STATUS_OK = 0
STATUS_NULL_ARGUMENT = 1
STATUS_INVALID_ARGUMENT = 2
STATUS_INVALID_MESH = 3
STATUS_IO = 4
STATUS_BUFFER_TOO_SMALL = 5
STATUS_UNSTABLE = 6
STATUS_UNSUPPORTED = 7
STATUS_POISONED = 8
STATUS_INTERNAL = 9

INTEGRATOR_EXPLICIT_EULER = 0
INTEGRATOR_SYMPLECTIC_EULER = 1
INTEGRATOR_IMPLICIT_EULER = 2
INTEGRATOR_XPBD = 3
CURVATURE_MEAN = 0
CURVATURE_GAUSSIAN = 1
SOLVER_XPBD = 0
SOLVER_PBD = 1
SOLVER_PBD_DISTANCE = 2  # on the shell branch (edge-distance baseline); harmless before it lands
MATERIAL_STVK = 0
MATERIAL_COROTATED = 1
MATERIAL_LINEAR = 2
MATERIAL_NEO_HOOKEAN = 3
MATERIAL_MOONEY_RIVLIN = 4
BENDING_NONE = 0
BENDING_ISOMETRIC = 1
BENDING_ISOMETRIC_REST = 2
ANISOTROPY_ARAP = 0
ANISOTROPY_STVK = 1
ANISOTROPY_SQRT = 2
# Scalars of the simulators' PLY output (colour_by of save_ply).
SHELL_PLY_MEAN_CURVATURE = 0
SHELL_PLY_GAUSSIAN_CURVATURE = 1
SHELL_PLY_ENERGY = 2
SHELL_PLY_PRESSURE_FORCE = 3
BODY_PLY_SPEED = 0
BODY_PLY_FRAGMENT = 1
BODY_PLY_MEAN_CURVATURE = 2
LATTICE_PLY_HEIGHT = 0
LATTICE_PLY_SPEED = 1
LATTICE_PLY_GOAL_DISTANCE = 2

# ---------------------------------------------------------------------------------------------
# Structs, field by field as in softshell.h (test_binding.py checks sizes and offsets with cc).

_f3 = ctypes.c_float * 3


class _Struct(ctypes.Structure):
    """A C struct that prints its fields and converts to a dict."""

    def as_dict(self):
        out = {}
        for name, _ in self._fields_:
            value = getattr(self, name)
            out[name] = list(value) if isinstance(value, ctypes.Array) else value
        return out

    def __repr__(self):
        fields = ", ".join(f"{k}={v!r}" for k, v in self.as_dict().items() if k != "internal_cookie")
        return f"{type(self).__name__}({fields})"


class BodyDef(_Struct):
    _fields_ = [
        ("time_step", ctypes.c_float),
        ("substeps", ctypes.c_uint32),
        ("integrator", ctypes.c_uint32),
        ("total_mass", ctypes.c_float),
        ("spring_stiffness", ctypes.c_float),
        ("spring_damping", ctypes.c_float),
        ("gas_amount", ctypes.c_float),
        ("gravity", _f3),
        ("wind", _f3),
        ("drag", ctypes.c_float),
        ("break_strain", ctypes.c_float),
        ("break_force", ctypes.c_float),
        ("leak_rate", ctypes.c_float),
        ("ground", ctypes.c_bool),
        ("ground_height", ctypes.c_float),
        ("restitution", ctypes.c_float),
        ("friction", ctypes.c_float),
        ("threads", ctypes.c_uint32),
        ("iterations", ctypes.c_uint32),
        ("internal_cookie", ctypes.c_uint32),
    ]


class BodyStats(_Struct):
    _fields_ = [
        ("step", ctypes.c_uint64),
        ("time", ctypes.c_double),
        ("volume", ctypes.c_double),
        ("pressure", ctypes.c_double),
        ("kinetic_energy", ctypes.c_double),
        ("energy_drift", ctypes.c_double),
        ("springs_broken", ctypes.c_uint64),
        ("cores_released", ctypes.c_uint64),
        ("topology_generation", ctypes.c_uint64),
        ("vertex_count", ctypes.c_size_t),
        ("triangle_count", ctypes.c_size_t),
        ("fragment_count", ctypes.c_size_t),
        ("step_seconds", ctypes.c_double),
        ("volume_clamped", ctypes.c_bool),
        ("max_strain", ctypes.c_double),
        ("solver_iterations", ctypes.c_uint64),
    ]


class LatticeDef(_Struct):
    _fields_ = [
        ("columns", ctypes.c_uint32),
        ("rows", ctypes.c_uint32),
        ("spacing", ctypes.c_float),
        ("region_half_width", ctypes.c_uint32),
        ("stiffness", ctypes.c_float),
        ("damping", ctypes.c_float),
        ("time_step", ctypes.c_float),
        ("particle_mass", ctypes.c_float),
        ("gravity", _f3),
        ("threads", ctypes.c_uint32),
        ("velocity_damping", ctypes.c_float),
        ("internal_cookie", ctypes.c_uint32),
    ]


class LatticeStats(_Struct):
    _fields_ = [
        ("step", ctypes.c_uint64),
        ("time", ctypes.c_double),
        ("goal_distance", ctypes.c_double),
        ("step_seconds", ctypes.c_double),
        ("max_goal_distance", ctypes.c_double),
        ("kinetic_energy", ctypes.c_double),
    ]


class MeshReport(_Struct):
    _fields_ = [
        ("vertex_count", ctypes.c_size_t),
        ("edge_count", ctypes.c_size_t),
        ("triangle_count", ctypes.c_size_t),
        ("boundary_edges", ctypes.c_size_t),
        ("non_manifold_edges", ctypes.c_size_t),
        ("degenerate_triangles", ctypes.c_size_t),
        ("components", ctypes.c_size_t),
        ("genus", ctypes.c_int32),
        ("is_closed", ctypes.c_bool),
        ("is_consistently_oriented", ctypes.c_bool),
        ("area", ctypes.c_double),
        ("volume", ctypes.c_double),
        ("bbox_min", _f3),
        ("bbox_max", _f3),
        ("non_manifold_vertices", ctypes.c_size_t),
        ("unreferenced_vertices", ctypes.c_size_t),
        ("min_angle_degrees", ctypes.c_double),
    ]


class ShellDef(_Struct):
    _fields_ = [
        ("time_step", ctypes.c_float),
        ("substeps", ctypes.c_uint32),
        ("iterations", ctypes.c_uint32),
        ("solver", ctypes.c_uint32),
        ("pressure", ctypes.c_float),
        ("material", ctypes.c_uint32),
        ("youngs_modulus", ctypes.c_float),
        ("poisson_ratio", ctypes.c_float),
        ("thickness", ctypes.c_float),
        ("density", ctypes.c_float),
        ("bending", ctypes.c_uint32),
        ("bending_coefficient", ctypes.c_float),
        ("damping", ctypes.c_float),
        ("stop_volume_ratio", ctypes.c_float),
        ("collisions", ctypes.c_bool),
        ("collision_thickness", ctypes.c_float),
        ("threads", ctypes.c_uint32),
        ("internal_cookie", ctypes.c_uint32),
    ]


class AnisotropyDef(_Struct):
    _fields_ = [
        ("energy", ctypes.c_uint32),
        ("stiffness", ctypes.c_float),
        ("inward_push", ctypes.c_float),
        ("target_stretch", ctypes.c_float),
        ("direction", _f3),
        ("internal_cookie", ctypes.c_uint32),
    ]


class ShellStats(_Struct):
    _fields_ = [
        ("step", ctypes.c_uint64),
        ("time", ctypes.c_double),
        ("volume", ctypes.c_double),
        ("volume_ratio", ctypes.c_double),
        ("finished", ctypes.c_bool),
        ("residual", ctypes.c_double),
        ("elastic_energy", ctypes.c_double),
        ("bending_energy", ctypes.c_double),
        ("anisotropic_energy", ctypes.c_double),
        ("collision_candidates", ctypes.c_uint64),
        ("ccd_tests", ctypes.c_uint64),
        ("contacts", ctypes.c_uint64),
        ("step_seconds", ctypes.c_double),
        ("stalled", ctypes.c_bool),
    ]


# The C struct names, for test_binding.py.
STRUCTS = {
    "SoftshellBodyDef": BodyDef,
    "SoftshellBodyStats": BodyStats,
    "SoftshellLatticeDef": LatticeDef,
    "SoftshellLatticeStats": LatticeStats,
    "SoftshellMeshReport": MeshReport,
    "SoftshellShellDef": ShellDef,
    "SoftshellAnisotropyDef": AnisotropyDef,
    "SoftshellShellStats": ShellStats,
}

# ---------------------------------------------------------------------------------------------
# Loading the library and declaring every function.


def _candidates():
    names = {"darwin": ["libsoftshell.dylib"], "win32": ["softshell.dll"]}.get(sys.platform, ["libsoftshell.so"])
    env = os.environ.get("SOFTSHELL_LIBRARY")
    if env:
        yield env
        return
    here = os.path.dirname(os.path.abspath(__file__))
    root = os.path.dirname(os.path.dirname(here))
    dirs = []
    if os.environ.get("CARGO_TARGET_DIR"):
        dirs.append(os.path.join(os.environ["CARGO_TARGET_DIR"], "release"))
    dirs.append(os.path.join(root, "target", "release"))
    for d in dirs:
        for n in names:
            yield os.path.join(d, n)
    found = ctypes.util.find_library("softshell")
    if found:
        yield found


def _load():
    tried = []
    for path in _candidates():
        if os.path.sep in path and not os.path.exists(path):
            tried.append(path)
            continue
        try:
            return ctypes.CDLL(path), path
        except OSError as e:
            tried.append(f"{path} ({e})")
    raise ImportError(
        "softshell: cannot find the shared library; build it with `cargo build --release` or set "
        "SOFTSHELL_LIBRARY to its path. Tried: " + "; ".join(tried))


_lib, library_path = _load()

_Status = ctypes.c_uint32
_h = ctypes.c_void_p  # every handle is opaque
_pf = ctypes.POINTER(ctypes.c_float)
_pu32 = ctypes.POINTER(ctypes.c_uint32)
_pd = ctypes.POINTER(ctypes.c_double)
_psize = ctypes.POINTER(ctypes.c_size_t)
_copy_f = [_h, _pf, ctypes.c_size_t, _psize]
_copy_u = [_h, _pu32, ctypes.c_size_t, _psize]

_SIGNATURES = {
    "softshell_abi_version": (ctypes.c_uint32, []),
    "softshell_version_string": (ctypes.c_char_p, []),
    "softshell_status_name": (ctypes.c_char_p, [ctypes.c_uint32]),
    "softshell_last_error": (ctypes.c_char_p, []),
    # meshes
    "softshell_mesh_from_arrays": (_Status, [_pf, ctypes.c_size_t, _pu32, ctypes.c_size_t, ctypes.POINTER(_h)]),
    "softshell_mesh_load_obj": (_Status, [ctypes.c_char_p, ctypes.POINTER(_h)]),
    "softshell_mesh_save_obj": (_Status, [_h, ctypes.c_char_p]),
    "softshell_mesh_save_ply": (_Status, [_h, ctypes.c_char_p, ctypes.c_uint32]),
    "softshell_mesh_free": (None, [_h]),
    "softshell_mesh_vertex_count": (ctypes.c_size_t, [_h]),
    "softshell_mesh_triangle_count": (ctypes.c_size_t, [_h]),
    "softshell_mesh_report": (_Status, [_h, ctypes.POINTER(MeshReport)]),
    "softshell_mesh_copy_positions": (_Status, _copy_f),
    "softshell_mesh_copy_triangles": (_Status, _copy_u),
    "softshell_mesh_copy_vertex_curvature": (_Status, [_h, ctypes.c_uint32, _pf, ctypes.c_size_t, _psize]),
    # shell
    "softshell_shell_def_default": (ShellDef, []),
    "softshell_anisotropy_def_default": (AnisotropyDef, []),
    "softshell_shell_new": (_Status, [_h, ctypes.POINTER(ShellDef), ctypes.POINTER(_h)]),
    "softshell_shell_free": (None, [_h]),
    "softshell_shell_add_anisotropic_region": (_Status, [_h, _pu32, ctypes.c_size_t, ctypes.POINTER(AnisotropyDef)]),
    "softshell_shell_step": (_Status, [_h, ctypes.POINTER(ShellStats)]),
    "softshell_shell_vertex_count": (ctypes.c_size_t, [_h]),
    "softshell_shell_copy_positions": (_Status, _copy_f),
    "softshell_shell_copy_face_energy": (_Status, _copy_f),
    "softshell_shell_copy_vertex_curvature": (_Status, [_h, ctypes.c_uint32, _pf, ctypes.c_size_t, _psize]),
    "softshell_shell_memory_bytes": (ctypes.c_size_t, [_h]),
    # body
    "softshell_body_def_default": (BodyDef, []),
    "softshell_body_new": (_Status, [_h, ctypes.POINTER(BodyDef), ctypes.POINTER(_h)]),
    "softshell_body_free": (None, [_h]),
    "softshell_body_add_sphere_obstacle": (_Status, [_h, _pf, ctypes.c_float]),
    "softshell_body_add_plane_obstacle": (_Status, [_h, _pf, _pf]),
    "softshell_body_pin_vertex": (_Status, [_h, ctypes.c_uint32]),
    "softshell_body_apply_impulse": (_Status, [_h, ctypes.c_uint32, _pf]),
    "softshell_body_break_edge": (_Status, [_h, ctypes.c_uint32, ctypes.c_uint32]),
    "softshell_body_break_edges": (_Status, [_h, _pu32, ctypes.c_size_t, _psize]),
    "softshell_body_step": (_Status, [_h, ctypes.POINTER(BodyStats)]),
    "softshell_body_topology_generation": (ctypes.c_uint64, [_h]),
    "softshell_body_vertex_count": (ctypes.c_size_t, [_h]),
    "softshell_body_triangle_count": (ctypes.c_size_t, [_h]),
    "softshell_body_fragment_count": (ctypes.c_size_t, [_h]),
    "softshell_body_memory_bytes": (ctypes.c_size_t, [_h]),
    "softshell_body_copy_positions": (_Status, _copy_f),
    "softshell_body_copy_velocities": (_Status, _copy_f),
    "softshell_body_copy_masses": (_Status, _copy_f),
    "softshell_body_copy_triangles": (_Status, _copy_u),
    "softshell_body_copy_vertex_origins": (_Status, _copy_u),
    "softshell_body_copy_fragment_ids": (_Status, _copy_u),
    # lattice
    "softshell_lattice_def_default": (LatticeDef, []),
    "softshell_lattice_new": (_Status, [ctypes.POINTER(LatticeDef), ctypes.POINTER(ctypes.c_uint8), ctypes.POINTER(_h)]),
    "softshell_lattice_free": (None, [_h]),
    "softshell_lattice_pin": (_Status, [_h, ctypes.c_uint32, ctypes.c_uint32]),
    "softshell_lattice_unpin": (_Status, [_h, ctypes.c_uint32, ctypes.c_uint32]),
    "softshell_lattice_apply_force": (_Status, [_h, ctypes.c_uint32, ctypes.c_uint32, _pf]),
    "softshell_lattice_clear_forces": (_Status, [_h]),
    "softshell_lattice_set_positions": (_Status, [_h, _pf, ctypes.c_size_t]),
    "softshell_lattice_step": (_Status, [_h, ctypes.POINTER(LatticeStats)]),
    "softshell_lattice_particle_count": (ctypes.c_size_t, [_h]),
    "softshell_lattice_triangle_count": (ctypes.c_size_t, [_h]),
    "softshell_lattice_memory_bytes": (ctypes.c_size_t, [_h]),
    "softshell_lattice_particle_index": (_Status, [_h, ctypes.c_uint32, ctypes.c_uint32, _pu32]),
    "softshell_lattice_copy_positions": (_Status, _copy_f),
    "softshell_lattice_copy_velocities": (_Status, _copy_f),
    "softshell_lattice_copy_goals": (_Status, _copy_f),
    "softshell_lattice_copy_triangles": (_Status, _copy_u),
    # collision queries
    "softshell_ccd_vertex_triangle": (_Status, [_pd] * 8 + [ctypes.c_double, ctypes.POINTER(ctypes.c_int32), _pd]),
    "softshell_ccd_edge_edge": (_Status, [_pd] * 8 + [ctypes.c_double, ctypes.POINTER(ctypes.c_int32), _pd]),
}

# Frame output (may be missing from an older library: then the methods raise Error(UNSUPPORTED)).
_OPTIONAL = {
    "softshell_shell_save_ply": (_Status, [_h, ctypes.c_char_p, ctypes.c_uint32]),
    "softshell_body_save_ply": (_Status, [_h, ctypes.c_char_p, ctypes.c_uint32]),
    "softshell_lattice_save_ply": (_Status, [_h, ctypes.c_char_p, ctypes.c_uint32]),
    "softshell_shell_save_obj": (_Status, [_h, ctypes.c_char_p]),
    "softshell_body_save_obj": (_Status, [_h, ctypes.c_char_p]),
    "softshell_lattice_save_obj": (_Status, [_h, ctypes.c_char_p]),
}


class _Functions:
    pass


class _U32(ctypes.c_uint32):
    """A uint32 argument that refuses integers out of range instead of wrapping them."""

    @classmethod
    def from_param(cls, value):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < 2**32:
            raise ValueError(f"{value!r} is not an integer in [0, 2^32)")
        return ctypes.c_uint32(int(value))


C = _Functions()  # the raw C functions, with argtypes and restype set
for _name, (_res, _args) in list(_SIGNATURES.items()) + list(_OPTIONAL.items()):
    try:
        _fn = getattr(_lib, _name)
    except AttributeError:
        if _name in _OPTIONAL:
            continue
        raise
    _fn.restype = _res
    # Scalar uint32 arguments are range-checked: ctypes alone wraps 2**32 to 0 silently.
    _fn.argtypes = [_U32 if a is ctypes.c_uint32 else a for a in _args]
    setattr(C, _name[len("softshell_"):], _fn)

ABI_VERSION = (0 << 16) | (1 << 8) | 0  # the header this binding mirrors


def version():
    """The linked library's version, "major.minor.patch"."""
    return C.version_string().decode()


def status_name(status):
    return C.status_name(status).decode()


# ---------------------------------------------------------------------------------------------
# Errors


class Error(Exception):
    """A failed call: ``status`` (int), ``status_name`` ("INVALID_MESH"...) and ``message``."""

    def __init__(self, status, message):
        self.status = int(status)
        self.status_name = status_name(status)
        self.message = message
        super().__init__(f"{self.status_name}: {message}")


def _check(status):
    if status != STATUS_OK:
        raise Error(status, C.last_error().decode(errors="replace"))


def _call_optional(name, *args):
    fn = getattr(C, name, None)
    if fn is None:
        raise Error(STATUS_UNSUPPORTED, f"softshell_{name} is not in the library at {library_path}")
    _check(fn(*args))


# ---------------------------------------------------------------------------------------------
# Buffers


def _floats(a, name, columns=None):
    """A C-contiguous float32 copy (or view) of `a`, flattened; checked for shape."""
    arr = np.ascontiguousarray(a, dtype=np.float32)
    if columns is not None and arr.size % columns != 0:
        raise ValueError(f"{name}: {arr.size} values is not a multiple of {columns}")
    return arr.reshape(-1)


def _u32(a, name, columns=None):
    arr = np.asarray(a)
    if arr.size and (arr.dtype.kind not in "iu" or arr.min() < 0 or arr.max() > 0xFFFFFFFF):
        raise ValueError(f"{name}: indices must be integers in [0, 2^32)")
    arr = np.ascontiguousarray(arr, dtype=np.uint32).reshape(-1)
    if columns is not None and arr.size % columns != 0:
        raise ValueError(f"{name}: {arr.size} values is not a multiple of {columns}")
    return arr


def _ptr(arr, ctype):
    return arr.ctypes.data_as(ctypes.POINTER(ctype)) if arr.size else None


def _vec3(v, name):
    arr = _floats(v, name)
    if arr.size != 3:
        raise ValueError(f"{name}: 3 values expected, got {arr.size}")
    return (ctypes.c_float * 3)(*arr.tolist())


def _copy(fn, handle, dtype, *extra, columns=None):
    """Runs a `(out, capacity, out_len)` copy: once to size, once to fill."""
    needed = ctypes.c_size_t(0)
    status = fn(handle, *extra, None, 0, ctypes.byref(needed))
    if status != STATUS_BUFFER_TOO_SMALL:
        _check(status)
    if needed.value == 0:
        # Nothing to copy (a lattice with no triangles): a NULL buffer would be refused as too small.
        out = np.empty(0, dtype=dtype)
        return out.reshape(-1, columns) if columns else out
    out = np.empty(needed.value, dtype=dtype)
    ctype = ctypes.c_float if dtype == np.float32 else ctypes.c_uint32
    _check(fn(handle, *extra, _ptr(out, ctype), out.size, ctypes.byref(needed)))
    out = out[: needed.value]
    return out.reshape(-1, columns) if columns else out


def _def(factory, base, overrides):
    d = factory() if base is None else base
    for key, value in overrides.items():
        if not hasattr(d, key) or key == "internal_cookie":
            raise AttributeError(f"{type(d).__name__} has no field `{key}`")
        field = getattr(d, key)
        kind = dict(d._fields_)[key]
        if isinstance(field, ctypes.Array):
            field[:] = list(value)
        else:
            if kind is ctypes.c_uint32 and (
                isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < 2**32
            ):
                raise ValueError(f"{key}: {value!r} is not an integer in [0, 2^32)")
            setattr(d, key, value)
    return d


def shell_def(**fields):
    """ShellDef with the library's defaults, then `fields` set."""
    return _def(C.shell_def_default, None, fields)


def anisotropy_def(**fields):
    return _def(C.anisotropy_def_default, None, fields)


def body_def(**fields):
    return _def(C.body_def_default, None, fields)


def lattice_def(**fields):
    return _def(C.lattice_def_default, None, fields)


def _path(path):
    encoded = os.fsencode(path)
    if b"\0" in encoded:
        # The C side would stop at the NUL and use a shorter path than the one given.
        raise ValueError(f"embedded null byte in path {path!r}")
    return encoded


# ---------------------------------------------------------------------------------------------
# Handles


class _Handle:
    _free = None

    def __init__(self, raw):
        self._raw = raw
        self._free_fn = getattr(C, self._free)  # kept so __del__ works during interpreter shutdown

    @property
    def handle(self):
        if self._raw is None:
            raise ValueError(f"{type(self).__name__} is closed")
        return self._raw

    def close(self):
        """Frees the library object now (later calls raise ValueError)."""
        if self._raw is not None:
            self._free_fn(self._raw)
            self._raw = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


class Mesh(_Handle):
    """An immutable triangle mesh."""
    _free = "mesh_free"

    @classmethod
    def from_arrays(cls, positions, triangles):
        """`positions` (n, 3) and `triangles` (m, 3), counter-clockwise seen from outside."""
        p = _floats(positions, "positions", 3)
        t = _u32(triangles, "triangles", 3)
        raw = _h()
        _check(C.mesh_from_arrays(_ptr(p, ctypes.c_float), p.size // 3, _ptr(t, ctypes.c_uint32), t.size // 3,
                                  ctypes.byref(raw)))
        return cls(raw)

    @classmethod
    def load_obj(cls, path):
        raw = _h()
        _check(C.mesh_load_obj(_path(path), ctypes.byref(raw)))
        return cls(raw)

    def save_obj(self, path):
        _check(C.mesh_save_obj(self.handle, _path(path)))

    def save_ply(self, path, colour_by=CURVATURE_MEAN):
        _check(C.mesh_save_ply(self.handle, _path(path), colour_by))

    @property
    def vertex_count(self):
        return C.mesh_vertex_count(self.handle)

    @property
    def triangle_count(self):
        return C.mesh_triangle_count(self.handle)

    def report(self):
        r = MeshReport()
        _check(C.mesh_report(self.handle, ctypes.byref(r)))
        return r

    def positions(self):
        return _copy(C.mesh_copy_positions, self.handle, np.float32, columns=3)

    def triangles(self):
        return _copy(C.mesh_copy_triangles, self.handle, np.uint32, columns=3)

    def vertex_curvature(self, kind=CURVATURE_MEAN):
        return _copy(C.mesh_copy_vertex_curvature, self.handle, np.float32, kind)


class Shell(_Handle):
    """A closed shell squeezed by outside pressure (SPEC 1). `Shell(mesh, def=None, **fields)`."""
    _free = "shell_free"

    def __init__(self, mesh, def_=None, **fields):
        d = _def(C.shell_def_default, def_, fields)
        raw = _h()
        _check(C.shell_new(mesh.handle, ctypes.byref(d), ctypes.byref(raw)))
        super().__init__(raw)
        self._triangles = mesh.triangles()  # the shell keeps the mesh's triangles

    def add_anisotropic_region(self, faces, def_=None, **fields):
        f = _u32(faces, "faces")
        d = _def(C.anisotropy_def_default, def_, fields)
        _check(C.shell_add_anisotropic_region(self.handle, _ptr(f, ctypes.c_uint32), f.size, ctypes.byref(d)))

    def step(self, stats=True):
        """One time step; returns ShellStats (or None with stats=False: no extra energy pass)."""
        s = ShellStats() if stats else None
        _check(C.shell_step(self.handle, ctypes.byref(s) if stats else None))
        return s

    @property
    def vertex_count(self):
        return C.shell_vertex_count(self.handle)

    @property
    def memory_bytes(self):
        return C.shell_memory_bytes(self.handle)

    def positions(self):
        return _copy(C.shell_copy_positions, self.handle, np.float32, columns=3)

    def triangles(self):
        """The mesh's triangles, (m, 3) uint32 (they never change)."""
        return self._triangles.copy()

    def face_energy(self):
        return _copy(C.shell_copy_face_energy, self.handle, np.float32)

    def vertex_curvature(self, kind=CURVATURE_MEAN):
        return _copy(C.shell_copy_vertex_curvature, self.handle, np.float32, kind)

    def save_ply(self, path, colour_by=SHELL_PLY_MEAN_CURVATURE):
        _call_optional("shell_save_ply", self.handle, _path(path), colour_by)

    def save_obj(self, path):
        _call_optional("shell_save_obj", self.handle, _path(path))


class Body(_Handle):
    """A mass-spring soft body with gas and fracture (SPEC 2). `Body(mesh, def=None, **fields)`.

    Fracture appends vertices and rewrites triangles: re-read triangles(), vertex_origins() and
    fragment_ids() whenever topology_generation changes (see refresh())."""
    _free = "body_free"

    def __init__(self, mesh, def_=None, **fields):
        d = _def(C.body_def_default, def_, fields)
        raw = _h()
        _check(C.body_new(mesh.handle, ctypes.byref(d), ctypes.byref(raw)))
        super().__init__(raw)
        self._generation = None
        self._topology = None

    def add_sphere_obstacle(self, center, radius):
        _check(C.body_add_sphere_obstacle(self.handle, _vec3(center, "center"), radius))

    def add_plane_obstacle(self, point, normal):
        _check(C.body_add_plane_obstacle(self.handle, _vec3(point, "point"), _vec3(normal, "normal")))

    def pin_vertex(self, vertex):
        _check(C.body_pin_vertex(self.handle, vertex))

    def apply_impulse(self, vertex, impulse):
        _check(C.body_apply_impulse(self.handle, vertex, _vec3(impulse, "impulse")))

    def break_edge(self, a, b):
        _check(C.body_break_edge(self.handle, a, b))

    def break_edges(self, pairs):
        """Breaks the edges of `pairs` (vertex pairs, shape (k, 2)) in one topology change, all or
        none: if a pair is refused, nothing changes. Returns the springs broken."""
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if pairs.size and (pairs.min() < 0 or pairs.max() > 0xFFFFFFFF):
            raise ValueError("vertex indices must be in [0, 2**32)")
        pairs = np.ascontiguousarray(pairs, dtype=np.uint32)
        broken = ctypes.c_size_t(0)
        _check(C.body_break_edges(self.handle, pairs.ctypes.data_as(_pu32), len(pairs), ctypes.byref(broken)))
        return broken.value

    def cut_slit(self, vertex):
        """A pin prick: breaks the two edges from `vertex` to opposite sides of its ring of
        neighbours, a straight slit through it (a crack runs from a slit that opens; a cut that
        only frees one face's corner loads no other spring). `vertex` must be inside the surface
        (a closed ring of faces around it). Returns the slit's two ends."""
        triangles = self.triangles()
        faces = triangles[(triangles == vertex).any(axis=1)]
        if len(faces) == 0:
            raise ValueError(f"vertex {vertex} is in no face")
        # Each face (vertex, a, b) in winding order leads from a to b around the ring.
        after = {}
        for face in faces:
            c = int(np.flatnonzero(face == vertex)[0])
            after[int(face[(c + 1) % 3])] = int(face[(c + 2) % 3])
        ring = [next(iter(after))]
        while after.get(ring[-1], ring[0]) != ring[0] and len(ring) <= len(faces):
            ring.append(after[ring[-1]])
        if len(ring) != len(faces) or after.get(ring[-1]) != ring[0]:
            raise ValueError(f"vertex {vertex} has no closed ring of faces around it")
        ends = (ring[0], ring[len(ring) // 2])
        self.break_edges([(end, vertex) for end in ends])  # one change: both or neither
        return ends

    def step(self):
        s = BodyStats()
        _check(C.body_step(self.handle, ctypes.byref(s)))
        return s

    @property
    def topology_generation(self):
        return C.body_topology_generation(self.handle)

    @property
    def vertex_count(self):
        return C.body_vertex_count(self.handle)

    @property
    def triangle_count(self):
        return C.body_triangle_count(self.handle)

    @property
    def fragment_count(self):
        return C.body_fragment_count(self.handle)

    @property
    def memory_bytes(self):
        return C.body_memory_bytes(self.handle)

    def positions(self):
        return _copy(C.body_copy_positions, self.handle, np.float32, columns=3)

    def velocities(self):
        return _copy(C.body_copy_velocities, self.handle, np.float32, columns=3)

    def masses(self):
        return _copy(C.body_copy_masses, self.handle, np.float32)

    def triangles(self):
        return _copy(C.body_copy_triangles, self.handle, np.uint32, columns=3)

    def vertex_origins(self):
        return _copy(C.body_copy_vertex_origins, self.handle, np.uint32)

    def fragment_ids(self):
        return _copy(C.body_copy_fragment_ids, self.handle, np.uint32)

    def refresh(self):
        """(changed, topology): re-reads triangles, vertex_origins and fragment_ids when the
        topology generation moved since the last refresh; `topology` is a dict of them."""
        generation = self.topology_generation
        if generation == self._generation:
            return False, self._topology
        self._topology = {
            "generation": generation,
            "triangles": self.triangles(),
            "vertex_origins": self.vertex_origins(),
            "fragment_ids": self.fragment_ids(),
        }
        self._generation = generation
        return True, self._topology

    def save_ply(self, path, colour_by=BODY_PLY_SPEED):
        _call_optional("body_save_ply", self.handle, _path(path), colour_by)

    def save_obj(self, path):
        _call_optional("body_save_obj", self.handle, _path(path))


class Lattice(_Handle):
    """A FastLSM elastic sheet (SPEC 3). `Lattice(def=None, mask=None, **fields)`; `mask` is a
    (rows, columns) array of 0/1 (1 = particle)."""
    _free = "lattice_free"

    def __init__(self, def_=None, mask=None, **fields):
        d = _def(C.lattice_def_default, def_, fields)
        m = None
        if mask is not None:
            m = np.ascontiguousarray(mask, dtype=np.uint8).reshape(-1)
            if m.size != d.columns * d.rows:
                raise ValueError(f"mask has {m.size} entries, columns * rows = {d.columns * d.rows}")
        raw = _h()
        _check(C.lattice_new(ctypes.byref(d), _ptr(m, ctypes.c_uint8) if m is not None else None, ctypes.byref(raw)))
        super().__init__(raw)
        self.columns, self.rows = d.columns, d.rows

    def pin(self, column, row):
        _check(C.lattice_pin(self.handle, column, row))

    def unpin(self, column, row):
        _check(C.lattice_unpin(self.handle, column, row))

    def apply_force(self, column, row, force):
        _check(C.lattice_apply_force(self.handle, column, row, _vec3(force, "force")))

    def clear_forces(self):
        """Drops the forces given since the last step (an Unstable step leaves them pending)."""
        _check(C.lattice_clear_forces(self.handle))

    def set_positions(self, positions):
        p = _floats(positions, "positions", 3)
        _check(C.lattice_set_positions(self.handle, _ptr(p, ctypes.c_float), p.size))

    def step(self):
        s = LatticeStats()
        _check(C.lattice_step(self.handle, ctypes.byref(s)))
        return s

    @property
    def particle_count(self):
        return C.lattice_particle_count(self.handle)

    @property
    def triangle_count(self):
        return C.lattice_triangle_count(self.handle)

    @property
    def memory_bytes(self):
        return C.lattice_memory_bytes(self.handle)

    def particle_index(self, column, row):
        out = ctypes.c_uint32()
        _check(C.lattice_particle_index(self.handle, column, row, ctypes.byref(out)))
        return out.value

    def positions(self):
        return _copy(C.lattice_copy_positions, self.handle, np.float32, columns=3)

    def velocities(self):
        return _copy(C.lattice_copy_velocities, self.handle, np.float32, columns=3)

    def goals(self):
        return _copy(C.lattice_copy_goals, self.handle, np.float32, columns=3)

    def triangles(self):
        return _copy(C.lattice_copy_triangles, self.handle, np.uint32, columns=3)

    def save_ply(self, path, colour_by=LATTICE_PLY_HEIGHT):
        _call_optional("lattice_save_ply", self.handle, _path(path), colour_by)

    def save_obj(self, path):
        _call_optional("lattice_save_obj", self.handle, _path(path))


# ---------------------------------------------------------------------------------------------
# Continuous collision queries


def _ccd(fn, points, thickness):
    arrays = []
    for i, p in enumerate(points):
        a = np.asarray(p, dtype=np.float64).reshape(-1)
        if a.size != 3:
            raise ValueError(f"point {i}: 3 coordinates expected, got {a.size}")
        arrays.append((ctypes.c_double * 3)(*a.tolist()))
    hit, toi = ctypes.c_int32(0), ctypes.c_double(1.0)
    _check(fn(*arrays, float(thickness), ctypes.byref(hit), ctypes.byref(toi)))
    return bool(hit.value), toi.value


def ccd_vertex_triangle(p0, a0, b0, c0, p1, a1, b1, c1, thickness=0.0):
    """(hit, toi): vertex p against triangle abc moving linearly from the *0 to the *1 positions."""
    return _ccd(C.ccd_vertex_triangle, (p0, a0, b0, c0, p1, a1, b1, c1), thickness)


def ccd_edge_edge(a0, b0, c0, d0, a1, b1, c1, d1, thickness=0.0):
    """(hit, toi): edge ab against edge cd moving linearly from the *0 to the *1 positions."""
    return _ccd(C.ccd_edge_edge, (a0, b0, c0, d0, a1, b1, c1, d1), thickness)
