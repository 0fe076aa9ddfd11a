// a plate with a circular hole: inflow on the left, outflow on the right, walls, hole
lc = 0.08;
Point(1) = {0, 0, 0, lc}; Point(2) = {2, 0, 0, lc}; Point(3) = {2, 1, 0, lc}; Point(4) = {0, 1, 0, lc};
Point(5) = {0.7, 0.5, 0, lc/2}; Point(6) = {0.9, 0.5, 0, lc/2}; Point(7) = {0.5, 0.5, 0, lc/2};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Circle(5) = {6, 5, 7}; Circle(6) = {7, 5, 6};
Curve Loop(1) = {1, 2, 3, 4}; Curve Loop(2) = {5, 6};
Plane Surface(1) = {1, 2};
Physical Curve("inflow") = {4};
Physical Curve("outflow") = {2};
Physical Curve("wall") = {1, 3};
Physical Curve("hole") = {5, 6};
Physical Surface("plate") = {1};
