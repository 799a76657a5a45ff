// A steel beam with holes, 1 m x 60 mm in the plane, its top face at y = 0,
// seven round holes of 36 mm on its mid-line, 125 mm apart: the body of
// cases/beam_with_holes.toml.  Made with Gmsh 4.15.2 (the `mesh` extra):
//
//   gmsh cases/beam_with_holes.geo -2 -format msh41 -o cases/beam_with_holes.msh
//
// Lengths in metres.  First-order triangles (cosim raises them to P2
// itself); 10 mm at the corners, 5 mm on the holes.
L = 1.0;          // length [m]
H = 0.06;         // height [m]
R = 0.018;        // hole radius [m]
N = 7;            // holes, at x = L k / (N + 1), y = -H / 2
lc = 0.01;        // element size at the outer corners [m]
lh = 0.005;       // element size on the holes [m]

Point(1) = {0, -H, 0, lc};
Point(2) = {L, -H, 0, lc};
Point(3) = {L, 0, 0, lc};
Point(4) = {0, 0, 0, lc};
Point(5) = {0, -H / 2, 0, lc};    // the pin: mid-height of the left end

Line(1) = {1, 2};                 // bottom
Line(2) = {2, 3};                 // right, upwards
Line(3) = {4, 3};                 // top, left to right: its arc length is x
Line(4) = {4, 5};                 // left, downwards
Line(5) = {5, 1};
Curve Loop(1) = {1, 2, -3, 4, 5};

loops[] = {1};
arcs[] = {};
For k In {1:N}
  xc = L * k / (N + 1);
  c = newp; Point(c) = {xc, -H / 2, 0, lh};
  p1 = newp; Point(p1) = {xc + R, -H / 2, 0, lh};
  p2 = newp; Point(p2) = {xc, -H / 2 + R, 0, lh};
  p3 = newp; Point(p3) = {xc - R, -H / 2, 0, lh};
  p4 = newp; Point(p4) = {xc, -H / 2 - R, 0, lh};
  a1 = newc; Circle(a1) = {p1, c, p2};
  a2 = newc; Circle(a2) = {p2, c, p3};
  a3 = newc; Circle(a3) = {p3, c, p4};
  a4 = newc; Circle(a4) = {p4, c, p1};
  h = newcl; Curve Loop(h) = {a1, a2, a3, a4};
  loops[] += {h};
  arcs[] += {a1, a2, a3, a4};
EndFor
Plane Surface(1) = {loops[]};

Physical Point("pin") = {5};
Physical Curve("bottom") = {1};
Physical Curve("right") = {2};
Physical Curve("top") = {3};
Physical Curve("left") = {4, 5};
Physical Curve("holes") = {arcs[]};
Physical Surface("beam") = {1};

Mesh.ElementOrder = 1;
Mesh.Algorithm = 6;               // Frontal-Delaunay
Mesh.RandomSeed = 1;
General.NumThreads = 1;           // the same mesh on every machine's run
