"""Tests of the ctypes binding (softshell.py) against the C header and the library:
struct layouts compiled with cc, constants and function list parsed from include/softshell.h,
errors raised with the status and message, buffers round-tripped through numpy.

    python3 c_examples/python/test_binding.py      (exit status 0 when every test passes)
"""

import ctypes
import os
import re
import shutil
import subprocess
import sys
import tempfile
import unittest

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import softshell  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HEADER = os.path.join(ROOT, "include", "softshell.h")

TETRA_P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float32)
TETRA_T = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]], dtype=np.uint32)


def header_text():
    with open(HEADER) as f:
        return f.read()


class Layout(unittest.TestCase):
    def test_struct_sizes_and_offsets_match_the_c_compiler(self):
        cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
        if not cc:
            self.skipTest("no C compiler")
        lines = ["#include <stdio.h>", "#include <stddef.h>", '#include "softshell.h"', "int main(void) {"]
        expected = []
        for cname, py in softshell.STRUCTS.items():
            lines.append(f'  printf("%zu %zu\\n", sizeof({cname}), _Alignof({cname}));')
            expected.append((f"{cname} size/align", f"{ctypes.sizeof(py)} {ctypes.alignment(py)}"))
            for field, _ in py._fields_:
                lines.append(f'  printf("%zu\\n", offsetof({cname}, {field}));')
                expected.append((f"{cname}.{field} offset", str(getattr(py, field).offset)))
        lines += ["  return 0;", "}"]
        with tempfile.TemporaryDirectory() as tmp:
            src, exe = os.path.join(tmp, "layout.c"), os.path.join(tmp, "layout")
            with open(src, "w") as f:
                f.write("\n".join(lines) + "\n")
            subprocess.run([cc, "-std=c11", "-I", os.path.join(ROOT, "include"), src, "-o", exe], check=True)
            got = subprocess.run([exe], check=True, capture_output=True, text=True).stdout.splitlines()
        self.assertEqual(len(got), len(expected))
        for (what, want), have in zip(expected, got):
            self.assertEqual(have, want, what)

    def test_every_struct_field_of_the_header_is_mirrored(self):
        text = header_text()
        for cname, py in softshell.STRUCTS.items():
            body = re.search(r"typedef struct %s \{(.*?)\} %s;" % (cname, cname), text, re.S).group(1)
            body = re.sub(r"//[^\n]*", "", body)
            fields = re.findall(r"(\w+)(?:\[\d+\])?;", body)
            self.assertEqual(fields, [f for f, _ in py._fields_], cname)
        structs = set(re.findall(r"typedef struct (Softshell\w+) \{", text))
        self.assertEqual(structs, set(softshell.STRUCTS), "a struct of the header is not mirrored")

    def test_constants_match_the_header(self):
        text = header_text()
        defines = dict(re.findall(r"#define SOFTSHELL_(\w+) (\d+)\s*$", text, re.M))
        for name, value in defines.items():
            if name.startswith("VERSION_"):
                continue
            self.assertTrue(hasattr(softshell, name), f"SOFTSHELL_{name} is not in softshell.py")
            self.assertEqual(getattr(softshell, name), int(value), name)
        statuses = dict(re.findall(r"SOFTSHELL_STATUS_(\w+) = (\d+)", text))
        for name, value in statuses.items():
            self.assertEqual(getattr(softshell, "STATUS_" + name), int(value), name)
            self.assertEqual(softshell.status_name(int(value)), name)

    def test_every_function_of_the_header_is_declared(self):
        names = set(re.findall(r"\b(softshell_\w+)\(", header_text()))
        names = {n for n in names if re.search(r"^[A-Za-z].*\b%s\(" % n, header_text(), re.M)}
        declared = set(softshell._SIGNATURES) | set(softshell._OPTIONAL)
        self.assertEqual(sorted(names - declared), [], "functions of the header missing from softshell.py")
        for name in names:
            self.assertTrue(hasattr(softshell.C, name[len("softshell_"):]), name)

    def test_version(self):
        self.assertEqual(softshell.C.abi_version(), softshell.ABI_VERSION)
        self.assertRegex(softshell.version(), r"^\d+\.\d+\.\d+$")


class Errors(unittest.TestCase):
    def test_invalid_mesh_raises_with_status_and_message(self):
        with self.assertRaises(softshell.Error) as caught:
            softshell.Mesh.from_arrays(TETRA_P, [[0, 1, 9]])
        e = caught.exception
        self.assertEqual(e.status, softshell.STATUS_INVALID_MESH)
        self.assertEqual(e.status_name, "INVALID_MESH")
        self.assertIn("index 9", e.message)
        self.assertIn("INVALID_MESH", str(e))

    def test_bad_def_field_names_the_field(self):
        mesh = softshell.Mesh.from_arrays(TETRA_P, TETRA_T)
        with self.assertRaises(softshell.Error) as caught:
            softshell.Shell(mesh, poisson_ratio=0.7)
        self.assertEqual(caught.exception.status_name, "INVALID_ARGUMENT")
        self.assertIn("poisson_ratio", caught.exception.message)
        with self.assertRaises(AttributeError):
            softshell.shell_def(no_such_field=1)

    def test_a_def_not_made_by_its_default_is_refused(self):
        mesh = softshell.Mesh.from_arrays(TETRA_P, TETRA_T)
        with self.assertRaises(softshell.Error) as caught:
            softshell.Body(mesh, softshell.BodyDef())
        self.assertEqual(caught.exception.status, softshell.STATUS_INVALID_ARGUMENT)

    def test_io_unknown_kind_and_ccd_nan(self):
        with self.assertRaises(softshell.Error) as caught:
            softshell.Mesh.load_obj("/no/such/file.obj")
        self.assertIn(caught.exception.status_name, ("IO", "UNSUPPORTED"))
        mesh = softshell.Mesh.from_arrays(TETRA_P, TETRA_T)
        with self.assertRaises(softshell.Error) as caught:
            mesh.vertex_curvature(7)
        self.assertEqual(caught.exception.status_name, "INVALID_ARGUMENT")
        z = [0, 0, 0]
        with self.assertRaises(softshell.Error):
            softshell.ccd_vertex_triangle([float("nan"), 0, 0], z, [1, 0, 0], [0, 1, 0], z, z, [1, 0, 0], [0, 1, 0])

    def test_lattice_index_errors_and_closed_handles(self):
        lattice = softshell.Lattice(columns=4, rows=3)
        with self.assertRaises(softshell.Error):
            lattice.pin(4, 0)
        with self.assertRaises(ValueError):
            softshell.Lattice(columns=4, rows=3, mask=np.ones(5))
        lattice.close()
        with self.assertRaises(ValueError):
            lattice.step()

    def test_pending_forces_that_diverge_can_be_dropped(self):
        lattice = softshell.Lattice(columns=6, rows=5)
        big = np.finfo(np.float32).max
        lattice.apply_force(2, 2, [big, 0, 0])
        lattice.apply_force(2, 2, [big, 0, 0])
        with self.assertRaises(softshell.Error) as caught:
            lattice.step()
        self.assertEqual(caught.exception.status_name, "UNSTABLE")
        self.assertIn("clear_forces", str(caught.exception))
        lattice.clear_forces()
        lattice.step()

    def test_integers_out_of_range_are_refused_not_wrapped(self):
        # ctypes alone wraps 2**32 to 0: pin(2**32, 0) pinned column 0 (a review).
        lattice = softshell.Lattice(columns=4, rows=3)
        for column in (2**32, -1, 2**40 + 1):
            # ctypes reports the converter's ValueError as an ArgumentError naming the argument.
            with self.assertRaisesRegex(ctypes.ArgumentError, "not an integer in"):
                lattice.pin(column, 0)
        with self.assertRaises(ValueError):
            softshell.shell_def(threads=2**32)
        self.assertEqual(softshell.shell_def(threads=3).threads, 3)

    def test_a_path_with_a_null_byte_is_refused(self):
        # The C side would stop at the NUL: save_obj("x.obj\\0.backup") wrote x.obj (a review).
        positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float32)
        triangles = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]], dtype=np.uint32)
        mesh = softshell.Mesh.from_arrays(positions, triangles)
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "cut.obj")
            with self.assertRaises(ValueError):
                mesh.save_obj(path + "\0.backup")
            self.assertFalse(os.path.exists(path))

    def test_empty_copies_return_empty_arrays(self):
        # One row of particles has no triangles: the copy must not pass NULL and fail.
        lattice = softshell.Lattice(columns=5, rows=1)
        self.assertEqual(lattice.triangles().shape[0], 0)


class Buffers(unittest.TestCase):
    def test_mesh_round_trip(self):
        mesh = softshell.Mesh.from_arrays(TETRA_P.tolist(), TETRA_T.astype(np.int64))
        np.testing.assert_array_equal(mesh.positions(), TETRA_P)
        np.testing.assert_array_equal(mesh.triangles(), TETRA_T)
        self.assertEqual(mesh.positions().dtype, np.float32)
        self.assertEqual(mesh.triangles().dtype, np.uint32)
        r = mesh.report()
        self.assertTrue(r.is_closed)
        self.assertAlmostEqual(r.volume, 1 / 6, places=6)
        self.assertEqual(list(r.bbox_max), [1, 1, 1])

    def test_lattice_positions_round_trip(self):
        lattice = softshell.Lattice(columns=5, rows=4, spacing=0.1)
        self.assertEqual(lattice.particle_count, 20)
        p = lattice.positions()
        self.assertEqual(p.shape, (20, 3))
        self.assertAlmostEqual(float(p[lattice.particle_index(3, 2), 0]), 0.3, places=6)
        moved = p + np.float32([0, 0.25, 0])
        lattice.set_positions(moved)
        np.testing.assert_array_equal(lattice.positions(), moved)
        self.assertEqual(lattice.triangles().shape, (2 * 4 * 3, 3))

    def test_shell_body_buffers_and_stats(self):
        sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
        shell = softshell.Shell(sphere)
        stats = shell.step()
        self.assertEqual(stats.step, 1)
        self.assertEqual(shell.positions().shape, (sphere.vertex_count, 3))
        self.assertEqual(shell.face_energy().shape, (sphere.triangle_count,))
        self.assertIsNone(shell.step(stats=False))
        np.testing.assert_array_equal(shell.triangles(), sphere.triangles())
        shell.add_anisotropic_region(np.arange(10), target_stretch=0.9)

        body = softshell.Body(sphere, gas_amount=10.0)
        changed, topology = body.refresh()
        self.assertTrue(changed)
        self.assertEqual(topology["generation"], 0)
        np.testing.assert_array_equal(topology["vertex_origins"], np.arange(sphere.vertex_count))
        self.assertAlmostEqual(float(body.masses().sum()), 1.0, places=4)
        t = topology["triangles"]
        body.break_edge(int(t[0, 0]), int(t[0, 1]))
        body.break_edge(int(t[0, 1]), int(t[0, 2]))
        body.step()
        changed, topology = body.refresh()
        self.assertTrue(changed, "a cut must bump the topology generation")
        self.assertEqual(body.positions().shape, (body.vertex_count, 3))
        self.assertGreater(body.vertex_count, sphere.vertex_count)
        self.assertEqual(topology["fragment_ids"].shape, (body.triangle_count,))
        self.assertFalse(body.refresh()[0])

    def test_a_slit_opens_and_its_sides_cannot_be_cut_again(self):
        sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
        body = softshell.Body(sphere, gas_amount=10.0)
        v = int(body.triangles()[0][0])
        a, b = body.cut_slit(v)
        self.assertNotEqual(a, b)
        self.assertIn(v, np.unique(body.triangles()))
        self.assertEqual(body.vertex_count, sphere.vertex_count + 1, "the slit splits its middle vertex in two")
        # Each side of the slit is now an edge of one face: nothing left to part.
        with self.assertRaises(softshell.Error) as caught:
            body.break_edge(a, v)
        self.assertIn("INVALID_ARGUMENT", str(caught.exception))
        self.assertIn("one face", str(caught.exception))
        body.step()

    def test_a_cut_of_several_edges_is_all_or_nothing(self):
        sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
        body = softshell.Body(sphere, gas_amount=10.0)
        t = body.triangles()
        good = [(int(t[0, 0]), int(t[0, 1])), (int(t[0, 1]), int(t[0, 2]))]
        with self.assertRaises(softshell.Error) as caught:
            body.break_edges(good + [(int(t[0, 0]), int(t[0, 0]))])
        self.assertIn("pair 2", str(caught.exception))
        with self.assertRaises(ValueError):
            body.break_edges([(-1, 0)])  # not wrapped round to a large index
        self.assertEqual(body.topology_generation, 0)
        self.assertEqual(body.break_edges(good + [good[0][::-1]]), 2)
        self.assertEqual(body.topology_generation, 1, "one change for the whole cut")
        self.assertEqual(body.break_edges([]), 0)
        self.assertEqual(body.topology_generation, 1)
        body.step()

    def test_frames_are_written(self):
        sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
        shell = softshell.Shell(sphere)
        shell.step()
        sheet = softshell.Lattice(columns=6, rows=5)
        with tempfile.TemporaryDirectory() as tmp:
            ply = os.path.join(tmp, "shell.ply")
            shell.save_ply(ply, softshell.SHELL_PLY_PRESSURE_FORCE)
            with open(ply) as f:
                header = f.read().split("end_header")[0]
            for name in ("mean_curvature", "gaussian_curvature", "energy", "pressure_force", "red"):
                self.assertIn(f"property float {name}" if name != "red" else "property uchar red", header)
            self.assertIn(f"element vertex {sphere.vertex_count}", header)
            sheet.save_obj(os.path.join(tmp, "sheet.obj"))
            self.assertEqual(softshell.Mesh.load_obj(os.path.join(tmp, "sheet.obj")).vertex_count, 30)
            with self.assertRaises(softshell.Error) as caught:
                sheet.save_ply(os.path.join(tmp, "sheet.ply"), 9)
            self.assertEqual(caught.exception.status_name, "INVALID_ARGUMENT")

    def test_ccd(self):
        hit, toi = softshell.ccd_edge_edge([-1, 1, 0], [1, 1, 0], [0, 0, -1], [0, 0, 1], [-1, -1, 0], [1, -1, 0],
                                           [0, 0, -1], [0, 0, 1])
        self.assertTrue(hit)
        self.assertAlmostEqual(toi, 0.5, places=6)
        hit, toi = softshell.ccd_vertex_triangle([5, 1, 5], [0, 0, 0], [1, 0, 0], [0, 0, 1], [5, -1, 5], [0, 0, 0],
                                                 [1, 0, 0], [0, 0, 1])
        self.assertEqual((hit, toi), (False, 1.0))


if __name__ == "__main__":
    result = unittest.main(exit=False, verbosity=1).result
    failed = len(result.failures) + len(result.errors)
    print(f"{result.testsRun - failed} passed, {failed} failed")
    sys.exit(1 if failed else 0)
