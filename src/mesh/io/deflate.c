/* deflate.c — zlib streams (RFC 1950) for compressed VTU output, by zlib itself. A home-made
 * deflate with one fixed-Huffman block stood here before issue 57: its output was 1.53
 * times zlib's on mesh data, where fixed codes spend more bits on the doubles' bytes. zlib
 * is among the mesh layer's allowed libraries (DESIGN.md), and PETSc loads it anyway.
 * Level 3: a 40³-cube tetrahedral mesh with a P1 field and a quality array (17.8 MB in
 * binary) compresses to 3.53 MB in 0.15 s, the home-made deflate's time for 5.45 MB; level
 * 1 gives 3.75 MB in 0.09 s, 5 3.60 MB in 0.20 s, 6 (zlib's default) 3.55 MB in 0.45 s. */
#include "deflate.h"

#include <zlib.h>

size_t mesh_zlib_bound(size_t n) { return (size_t)compressBound((uLong)n); }

size_t mesh_zlib_compress(const unsigned char *in, size_t n, unsigned char *out, size_t cap) {
  uLongf len = (uLongf)cap;
  if ((size_t)(uLong)n != n || (size_t)(uLongf)cap != cap) return 0;
  if (compress2(out, &len, in, (uLong)n, 3) != Z_OK) return 0;
  return (size_t)len;
}
