"""softshell from Python: a mesh contracting under outside pressure, then a balloon inflated and
pricked until it bursts, re-reading the body's buffers after every topology change.

    python3 c_examples/python/demo.py [--mesh data/kitten.obj] [--frames DIR]

With --frames, PLY frames (coloured by curvature / fragment) are written to DIR for MeshLab,
Blender or ParaView. Prints one line per event; exits 1 on an unexpected outcome.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import softshell  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def unit_diagonal(mesh):
    """The mesh scaled about its centre to a unit bounding-box diagonal (the scale the shell's
    default settings are made for)."""
    p = mesh.positions()
    lo, hi = p.min(axis=0), p.max(axis=0)
    return softshell.Mesh.from_arrays((p - (lo + hi) / 2) / np.linalg.norm(hi - lo), mesh.triangles())


def contract(mesh, frames):
    shell = softshell.Shell(mesh, stop_volume_ratio=0.5)
    print(f"contraction: {mesh.vertex_count} vertices, {shell.memory_bytes} bytes")
    stats = None
    for i in range(300):
        stats = shell.step()
        if frames and i % 5 == 0:
            shell.save_ply(os.path.join(frames, f"contract_{i:04d}.ply"), softshell.SHELL_PLY_MEAN_CURVATURE)
        if i % 10 == 0 or stats.finished:
            print(f"  step {stats.step:3d}  V/V0 {stats.volume_ratio:.3f}  membrane {stats.elastic_energy:.3g} J"
                  f"  residual {stats.residual:.2g}")
        if stats.finished:
            break
    h = shell.vertex_curvature(softshell.CURVATURE_MEAN)
    e = shell.face_energy()
    print(f"  finished={stats.finished}: mean curvature in [{h.min():.3g}, {h.max():.3g}] 1/m,"
          f" face energy {e.sum():.3g} J over {e.size} faces")
    if frames:
        shell.save_ply(os.path.join(frames, "contract_last.ply"), softshell.SHELL_PLY_MEAN_CURVATURE)
    return stats.volume_ratio < 0.9


def burst(frames):
    sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
    body = softshell.Body(sphere, gas_amount=4500.0, break_strain=0.27, gravity=[0, 0, 0], spring_damping=2.0,
                          time_step=1 / 120)
    print(f"balloon: {body.vertex_count} vertices, gas nRT = 4500 J, cracks at 27% strain")
    changed, topology = body.refresh()
    positions = body.positions()
    pricked = False
    shown = 0  # topology changes printed
    for i in range(150):
        if i == 60:
            # A pin prick: a slit of two edges through one vertex.
            b = int(topology["triangles"][0][1])
            body.cut_slit(b)
            pricked = True
            print(f"  step {i}: pricked at vertex {b} (max strain {stats.max_strain:.2f}, volume {stats.volume:.2f})")
        stats = body.step()
        changed, topology = body.refresh()  # triangles, origins and fragments of this generation
        positions = body.positions()        # vertex count may have grown: always re-read
        assert positions.shape[0] == body.vertex_count
        assert topology["triangles"].max() < positions.shape[0], "stale triangles after a topology change"
        if changed and stats.step > 1:
            shown += 1
        if changed and stats.step > 1 and shown <= 6:
            print(f"  step {stats.step:3d}: generation {topology['generation']}, {stats.springs_broken} springs broke,"
                  f" {positions.shape[0]} vertices, {len(topology['triangles'])} triangles,"
                  f" {body.fragment_count} fragments")
        if frames and i >= 55 and i % 2 == 0:
            body.save_ply(os.path.join(frames, f"burst_{i:04d}.ply"), softshell.BODY_PLY_FRAGMENT)
    if shown > 6:
        print(f"  ... {shown - 6} more topology changes")
    origins = topology["vertex_origins"]
    print(f"  end: {body.fragment_count} fragments, {len(origins)} vertices split from {len(np.unique(origins))}"
          f" originals, kinetic energy {stats.kinetic_energy:.3g} J")
    if body.fragment_count == 1:
        print("  the balloon did not burst: fracture may be missing from this build; it only inflated")
    return pricked


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default=os.path.join(ROOT, "data", "kitten.obj"))
    parser.add_argument("--frames", help="directory for PLY frames")
    args = parser.parse_args()
    if args.frames:
        os.makedirs(args.frames, exist_ok=True)
    print(f"softshell {softshell.version()} from {softshell.library_path}")
    ok = contract(unit_diagonal(softshell.Mesh.load_obj(args.mesh)), args.frames)
    ok = burst(args.frames) and ok
    try:
        softshell.Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 5]])
        ok = False
    except softshell.Error as e:
        print(f"expected error: {e}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
