// unit cube, unstructured tetrahedra
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 1};
Mesh.CharacteristicLengthMax = 0.3;
Physical Surface("boundary") = {1, 2, 3, 4, 5, 6};
Physical Volume("domain") = {1};
