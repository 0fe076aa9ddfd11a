/* deflate.h — zlib-format compression (deflate.c), for compressed VTU output */
#ifndef LUGAL_DEFLATE_H
#define LUGAL_DEFLATE_H

#include <stddef.h>

/* the largest stream mesh_zlib_compress writes for n bytes */
size_t mesh_zlib_bound(size_t n);
/* a zlib stream of in[0..n) into out (cap bytes, mesh_zlib_bound(n) suffice); its length,
 * 0 when out was too small or memory ran out */
size_t mesh_zlib_compress(const unsigned char *in, size_t n, unsigned char *out, size_t cap);

#endif
