"""Write ``beam_2d.msh``: beam_impact's beam (1 m x 10 mm) meshed in the plane,
in Gmsh's MSH 2.2 ASCII layout (gmsh itself is not needed).

The rectangle ``[0, 1] x [-0.01, 0]`` m (its top face at y = 0, as the 1-D
beam's line), 100 x 2 squares each cut into two triangles, with the physical
groups a Gmsh script would give: curves ``bottom``, ``right``, ``top`` (left
to right, so that the arc length along it is x) and ``left``, the point
``pin`` at mid-height of the left end, and the surface ``beam``.

Run ``python tests/data/make_beam_2d_msh.py`` to write ``cases/beam_2d.msh`` again.
"""
from pathlib import Path

LX, LY, NX, NY = 1.0, 0.01, 100, 2


def build() -> str:
    def node(i, j):
        return i * (NY + 1) + j + 1                       # 1-based tags

    names = [(0, 1, "pin"), (1, 2, "bottom"), (1, 3, "right"), (1, 4, "top"), (1, 5, "left"),
             (2, 6, "beam")]
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(names))]
    out += [f'{d} {t} "{n}"' for d, t, n in names]
    out += ["$EndPhysicalNames", "$Nodes", str((NX + 1) * (NY + 1))]
    for i in range(NX + 1):
        for j in range(NY + 1):
            out.append(f"{node(i, j)} {LX * i / NX:.17g} {LY * j / NY - LY:.17g} 0")
    out.append("$EndNodes")
    rows = [f"15 2 1 1 {node(0, NY // 2)}"]                       # the pin
    rows += [f"1 2 2 1 {node(i, 0)} {node(i + 1, 0)}" for i in range(NX)]
    rows += [f"1 2 3 2 {node(NX, j)} {node(NX, j + 1)}" for j in range(NY)]
    rows += [f"1 2 4 3 {node(i, NY)} {node(i + 1, NY)}" for i in range(NX)]
    rows += [f"1 2 5 4 {node(0, j + 1)} {node(0, j)}" for j in range(NY - 1, -1, -1)]
    for i in range(NX):
        for j in range(NY):
            a, b, c, d = node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)
            rows += [f"2 2 6 1 {a} {b} {c}", f"2 2 6 1 {a} {c} {d}"]
    out += ["$Elements", str(len(rows))]
    out += [f"{k + 1} {r}" for k, r in enumerate(rows)]
    out.append("$EndElements")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    (Path(__file__).resolve().parents[2] / "cases" / "beam_2d.msh").write_text(build())
