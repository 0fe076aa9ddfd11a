#!/bin/sh
# test_vtu_zlib.sh BUILD — zlib-compressed VTU (src/mesh/deflate.c, vtk.c): every array of a
# format = "zlib" file, inflated by Python's zlib (the reference decompressor; python3 is
# part of Debian's base system) block by block from VTK's header, equals the same array of
# the plain binary file byte for byte, and the file is smaller.
BUILD=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cat > "$T/w.lua" <<LUA
local lg = require "lugal"
local mesh = lg.mesh.box{nx = 14, ny = 9, nz = 7}
local f = lg.interpolate(lg.lagrange(1), mesh, lg.sin(3*lg.x)*lg.y + lg.z, "f")
mesh:write("$T/b.vtu", {f = f, q = mesh:quality("mean_ratio")})
mesh:write("$T/z.vtu", {f = f, q = mesh:quality("mean_ratio")}, {format = "zlib"})
LUA
"$BUILD/lugal" "$T/w.lua" || { echo "FAIL: writing"; exit 1; }
command -v python3 > /dev/null || { echo "FAIL: python3 is needed to inflate"; exit 1; }
python3 - "$T/b.vtu" "$T/z.vtu" <<'PY' || exit 1
import base64, re, struct, sys, zlib, os
def arrays(path):
    return re.findall(r'<DataArray[^>]*>\n([^<]*)\n</DataArray>', open(path).read())
plain, comp = arrays(sys.argv[1]), arrays(sys.argv[2])
assert 'compressor="vtkZLibDataCompressor"' in open(sys.argv[2]).read(), "no compressor attribute"
assert len(plain) == len(comp) == 6, (len(plain), len(comp))
for p, c in zip(plain, comp):
    raw = base64.b64decode(p)
    n = struct.unpack('<Q', raw[:8])[0]
    data = raw[8:8 + n]
    nb = struct.unpack('<Q', base64.b64decode(c[:32])[:8])[0]
    hlen = 8 * (3 + nb)
    henc = 4 * ((hlen + 2) // 3)
    h = struct.unpack('<%dQ' % (3 + nb), base64.b64decode(c[:henc])[:hlen])
    z = base64.b64decode(c[henc:])
    out, at = b'', 0
    for k in range(nb):
        out += zlib.decompress(z[at:at + h[3 + k]]); at += h[3 + k]
    assert out == data, "an array differs after inflating"
    assert h[1] == 32768 and h[2] == len(data) % 32768, h[:3]
sb, sz = os.path.getsize(sys.argv[1]), os.path.getsize(sys.argv[2])
assert sz < sb / 2, (sz, sb)
print("zlib VTU: 6 arrays inflate to the binary file's bytes; %d bytes against %d" % (sz, sb))
PY
