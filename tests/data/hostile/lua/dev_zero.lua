-- expect: it does not start like a Gmsh MSH file
-- (/dev/zero, or an endless pipe of anything else, was read for 2 GiB before "out of memory";
-- now the first 4 KB of a pipe or device must be text opening with a section)
local lg = require "lugal"
lg.mesh.read("/dev/zero")
