"""Draw docs/torch_frame.png: the torch frame of a set-point on a curved plate.

Run from the repository root: ``.venv/bin/python docs/torch_frame.py``. It uses the library's own
set-point code (make_cutting_path on a synthetic arc on a cylinder), so the picture shows what
scrapcut writes, not a drawing of it. Deterministic (no random numbers); matplotlib Agg.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from scrapcut_cli.geometry import quat_xyzw_to_matrix

OUT = Path(__file__).with_name("torch_frame.png")


def main() -> None:
    # A curved plate: the top of a cylinder of radius 0.3 m along y; the painted line runs
    # along x over the crown, the surface normal points up and out.
    radius = 0.3
    x = np.linspace(-0.12, 0.12, 7)
    angle = x / radius
    surface = np.column_stack([radius * np.sin(angle), np.zeros_like(x), radius * np.cos(angle)])
    normals = surface / np.linalg.norm(surface, axis=1, keepdims=True)
    tangents = np.column_stack([np.cos(angle), np.zeros_like(x), -np.sin(angle)])
    from scrapcut_cli.geometry import matrix_to_quat_xyzw
    from scrapcut_cli.toolpath.setpoints import torch_rotations

    standoff = 0.03  # exaggerated (8 mm by default) so the tip is visible
    quats = matrix_to_quat_xyzw(torch_rotations(normals, tangents))
    tips = surface + standoff * normals

    fig = plt.figure(figsize=(7.0, 4.6), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    u = np.linspace(-0.5, 0.5, 30)
    v = np.linspace(-0.08, 0.08, 6)
    uu, vv = np.meshgrid(u, v)
    ax.plot_surface(
        radius * np.sin(uu), vv, radius * np.cos(uu), color="0.85", alpha=0.6, linewidth=0
    )
    ax.plot(*surface.T, color="tab:orange", linewidth=3, label="painted line (curve)")
    length = 0.035
    for k, (tip, q) in enumerate(zip(tips, quats, strict=True)):
        R = quat_xyzw_to_matrix(q)
        for axis, colour, name in ((0, "tab:red", "x: travel"), (1, "tab:green", "y = z × x"),
                                   (2, "tab:blue", "z: into the surface")):  # fmt: skip
            ax.quiver(*tip, *(length * R[:, axis]), color=colour, linewidth=1.6,
                      label=name if k == 0 else None)  # fmt: skip
        ax.plot(*np.stack([tip, surface[k]]).T, color="0.3", linestyle=":", linewidth=1)
    ax.scatter(*tips.T, color="black", s=12, label="torch tip (standoff above the surface)")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.set_box_aspect((0.26, 0.16, 0.1))
    ax.set_zlim(0.26, 0.36)
    ax.view_init(elev=22, azim=-60)
    ax.set_title("Torch frame of each set-point (orientation_xyzw)")
    ax.legend(loc="upper left", fontsize=8)
    fig.savefig(OUT, dpi=110, metadata={"Software": None})
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
