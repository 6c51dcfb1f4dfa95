"""Renders the README's pictures: a contraction, a burst and a poked sheet, three frames each.

Each frame is simulated through the Python binding (c_examples/python/softshell.py), written as a
PLY file by the library (softshell_*_save_ply, vertex colours from one scalar), read back and
drawn with matplotlib, lit by a fixed light so the shape reads. matplotlib is only needed here,
never by the library:

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install matplotlib numpy
    /tmp/venv/bin/python report/images/render.py        (writes report/images/*.png)
"""

import os
import sys
import tempfile

import numpy as np

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "c_examples", "python"))
import softshell  # noqa: E402

TMP = tempfile.mkdtemp(prefix="softshell-render-")


def read_ply(path):
    """Positions (n, 3), colours (n, 3) in [0, 1] and triangles (m, 3) of an ASCII PLY."""
    with open(path) as f:
        lines = f.read().splitlines()
    end = lines.index("end_header")
    header = lines[:end]
    nv = int(next(l.split()[2] for l in header if l.startswith("element vertex")))
    props = [l.split()[2] for l in header if l.startswith("property") and "list" not in l]
    rows = np.array([[float(w) for w in l.split()] for l in lines[end + 1:end + 1 + nv]])
    faces = np.array([[int(w) for w in l.split()[1:4]] for l in lines[end + 1 + nv:]], dtype=int)
    rgb = rows[:, [props.index("red"), props.index("green"), props.index("blue")]] / 255.0
    return rows[:, :3], rgb, faces


def draw(ax, ply, title, view=(20, -60), limits=None, aspect=None):
    p, rgb, t = read_ply(ply)
    p = p[:, [0, 2, 1]]  # y up in the library, z up in matplotlib
    tris = p[t]
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    shade = 0.55 + 0.45 * np.abs(n @ light)
    colours = np.clip(rgb[t].mean(axis=1) * shade[:, None], 0, 1)
    ax.add_collection3d(Poly3DCollection(tris, facecolors=colours, edgecolors="none", linewidths=0))
    # Robust limits: a few far-flung shreds must not shrink the picture to a dot.
    lo, hi = (np.percentile(p, 1, axis=0), np.percentile(p, 99, axis=0)) if limits is None else limits
    c = (lo + hi) / 2
    if aspect is None:  # a cube
        r = np.full(3, (hi - lo).max() / 2)
        aspect = (1, 1, 1)
    else:  # each axis its own range (a flat sheet with its dent exaggerated)
        r = np.maximum((hi - lo) / 2, 1e-6)
    ax.set_xlim(c[0] - r[0], c[0] + r[0])
    ax.set_ylim(c[1] - r[1], c[1] + r[1])
    ax.set_zlim(c[2] - r[2], c[2] + r[2])
    ax.set_box_aspect(aspect, zoom=1.35)
    ax.view_init(*view)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)
    return lo, hi


def strip(name, frames, view=(20, -60), shared_limits=False, aspect=None):
    fig = plt.figure(figsize=(7.5, 2.6), dpi=100)
    limits = None
    if shared_limits:
        ps = [read_ply(f)[0][:, [0, 2, 1]] for f, _ in frames]
        limits = (np.min([p.min(axis=0) for p in ps], axis=0), np.max([p.max(axis=0) for p in ps], axis=0))
    for i, (ply, title) in enumerate(frames):
        ax = fig.add_subplot(1, len(frames), i + 1, projection="3d")
        draw(ax, ply, title, view, limits, aspect)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.9, wspace=0)
    out = os.path.join(HERE, name)
    fig.savefig(out)
    plt.close(fig)
    print("wrote", out)


def contraction():
    mesh = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "kitten.obj"))
    p = mesh.positions()
    lo, hi = p.min(axis=0), p.max(axis=0)
    mesh = softshell.Mesh.from_arrays((p - (lo + hi) / 2) / np.linalg.norm(hi - lo), mesh.triangles())
    shell = softshell.Shell(mesh, stop_volume_ratio=0.45)
    frames, stats, i = [], None, 0
    while True:
        if i in (0, 20) or (stats is not None and stats.finished):
            path = os.path.join(TMP, f"contract_{i}.ply")
            shell.save_ply(path, softshell.SHELL_PLY_MEAN_CURVATURE)
            ratio = 1.0 if stats is None else stats.volume_ratio
            frames.append((path, f"step {i}: V/V0 = {ratio:.2f}"))
            if stats is not None and stats.finished:
                break
        stats = shell.step()
        i += 1
    strip("contraction.png", frames, view=(15, -70), shared_limits=True)


def burst():
    sphere = softshell.Mesh.load_obj(os.path.join(ROOT, "data", "sphere.obj"))
    body = softshell.Body(sphere, gas_amount=4500.0, break_strain=0.27, gravity=[0, 0, 0], spring_damping=2.0,
                          time_step=1 / 120)
    frames = []
    for i in range(68):
        if i == 60:
            body.cut_slit(int(body.triangles()[0][1]))
        if i in (59, 63, 67):
            path = os.path.join(TMP, f"burst_{i}.ply")
            body.save_ply(path, softshell.BODY_PLY_FRAGMENT)
            frames.append((path, f"step {i}: {body.fragment_count} piece{'s' if body.fragment_count > 1 else ''}"))
        body.step()
    strip("burst.png", frames, shared_limits=False)


def poked_sheet():
    sheet = softshell.Lattice(columns=40, rows=28, spacing=0.025, gravity=[0, 0, 0])
    for r in range(28):
        sheet.pin(0, r)
        sheet.pin(39, r)
    frames = []
    for i in range(61):
        if i < 8:
            for dc in (-1, 0, 1):
                for dr in (-1, 0, 1):
                    sheet.apply_force(20 + dc, 14 + dr, [0, -0.6, 0])
        if i in (8, 24, 60):
            path = os.path.join(TMP, f"sheet_{i}.ply")
            sheet.save_ply(path, softshell.LATTICE_PLY_GOAL_DISTANCE)
            frames.append((path, f"step {i}: strain |g - x|"))
        sheet.step()
    strip("poked_sheet.png", frames, view=(25, -60), shared_limits=True, aspect=(1.4, 1, 0.35))


if __name__ == "__main__":
    contraction()
    burst()
    poked_sheet()
