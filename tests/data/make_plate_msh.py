"""Write ``plate.msh``: a 200 mm x 50 mm plate in Gmsh's MSH 4.1 ASCII layout,
as Gmsh saves a mesh with physical groups (gmsh itself is not needed).

Geometry as a Gmsh script would give it: points 1-4 at the corners
(bottom-left first, counter-clockwise), curves 1 (bottom, 1 -> 2), 2 (right,
2 -> 3), 3 (top, 3 -> 4), 4 (left, 4 -> 1), surface 1 bounded by them, and
the physical groups ``Physical Curve("tip") = {2}``, ``("face") = {3}``,
``("clamp") = {4}``, ``Physical Surface("plate") = {1}``.  The bottom curve
is in no physical group, so (as Gmsh does) its line cells are not saved.
Nodes belong to the lowest-dimensional entity holding them; the mesh is
8 x 2 squares, each cut into two triangles.

Run ``python tests/data/make_plate_msh.py`` to write it again.
"""
from pathlib import Path

LX, LY, NX, NY = 200.0, 50.0, 8, 2


def build() -> str:
    def node(i, j):
        return i * (NY + 1) + j + 1                       # 1-based tags

    def xy(i, j):
        return LX * i / NX, LY * j / NY

    corners = {1: (0, 0), 2: (NX, 0), 3: (NX, NY), 4: (0, NY)}
    curves = {1: [(i, 0) for i in range(NX + 1)],
              2: [(NX, j) for j in range(NY + 1)],
              3: [(i, NY) for i in range(NX, -1, -1)],
              4: [(0, j) for j in range(NY, -1, -1)]}
    owner = {}
    for tag, ij in corners.items():
        owner[ij] = (0, tag)
    for tag, pts in curves.items():
        for ij in pts[1:-1]:
            owner[ij] = (1, tag)
    for i in range(NX + 1):
        for j in range(NY + 1):
            owner.setdefault((i, j), (2, 1))
    physical = {2: 11, 3: 12, 4: 13}                    # curve -> physical tag
    out = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$PhysicalNames", "4",
           '1 11 "tip"', '1 12 "face"', '1 13 "clamp"', '2 21 "plate"', "$EndPhysicalNames",
           "$Entities", "4 4 1 0"]
    for tag, ij in corners.items():
        x, y = xy(*ij)
        out.append(f"{tag} {x:g} {y:g} 0 0")
    ends = {1: (1, -2), 2: (2, -3), 3: (3, -4), 4: (4, -1)}
    for tag, pts in curves.items():
        xs = [xy(*ij)[0] for ij in pts]
        ys = [xy(*ij)[1] for ij in pts]
        phys = f"1 {physical[tag]}" if tag in physical else "0"
        out.append(f"{tag} {min(xs):g} {min(ys):g} 0 {max(xs):g} {max(ys):g} 0 {phys} 2 "
                   f"{ends[tag][0]} {ends[tag][1]}")
    out.append(f"1 0 0 0 {LX:g} {LY:g} 0 1 21 4 1 2 3 4")
    out.append("$EndEntities")
    blocks = {}
    for ij, ent in sorted(owner.items(), key=lambda kv: node(*kv[0])):
        blocks.setdefault(ent, []).append(ij)
    n_nodes = (NX + 1) * (NY + 1)
    out += ["$Nodes", f"{len(blocks)} {n_nodes} 1 {n_nodes}"]
    for (dim, tag), pts in sorted(blocks.items()):
        out.append(f"{dim} {tag} 0 {len(pts)}")
        out += [str(node(*ij)) for ij in pts]
        out += ["{:g} {:g} 0".format(*xy(*ij)) for ij in pts]
    out.append("$EndNodes")
    elements, tag = [], 1
    for c in (2, 3, 4):
        pts = curves[c]
        rows = []
        for a, b in zip(pts[:-1], pts[1:]):
            rows.append(f"{tag} {node(*a)} {node(*b)}")
            tag += 1
        elements.append((1, c, 1, rows))
    rows = []
    for i in range(NX):
        for j in range(NY):
            a, b, c, d = node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)
            rows += [f"{tag} {a} {b} {c}", f"{tag + 1} {a} {c} {d}"]
            tag += 2
    elements.append((2, 1, 2, rows))
    out += ["$Elements", f"{len(elements)} {tag - 1} 1 {tag - 1}"]
    for dim, ent, kind, rows in elements:
        out.append(f"{dim} {ent} {kind} {len(rows)}")
        out += rows
    out.append("$EndElements")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    Path(__file__).with_name("plate.msh").write_text(build())
