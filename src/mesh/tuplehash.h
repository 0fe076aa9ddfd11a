/* tuplehash.h — open-addressing hash map from sorted tuples of up to 4 vertex ids to an
 * int, used for edges, faces, facets and midpoints. Header-only, internal to src/mesh. */
#ifndef LUGAL_TUPLEHASH_H
#define LUGAL_TUPLEHASH_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  int k[4];
  int val;
} th_entry;

typedef struct {
  size_t cap, n;
  int klen;
  th_entry *e; /* val == -1 marks an empty slot */
} tuplehash;

static inline void th_sort(int *k, int n) {
  for (int i = 1; i < n; i++) {
    int v = k[i], j = i - 1;
    while (j >= 0 && k[j] > v) { k[j + 1] = k[j]; j--; }
    k[j + 1] = v;
  }
}

static inline uint64_t th_hash(const int *k, int n) {
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < n; i++) {
    h ^= (uint64_t)(uint32_t)k[i];
    h *= 0x9E3779B97F4A7C15ull;
    h ^= h >> 29;
  }
  return h;
}

static inline int th_init(tuplehash *t, size_t expected, int klen) {
  size_t cap = 16;
  while (cap < 2 * expected + 16) cap <<= 1;
  t->cap = cap;
  t->n = 0;
  t->klen = klen;
  t->e = malloc(cap * sizeof(th_entry));
  if (!t->e) return 1;
  for (size_t i = 0; i < cap; i++) t->e[i].val = -1;
  return 0;
}

static inline void th_free(tuplehash *t) { free(t->e); t->e = NULL; }

static inline int th_grow(tuplehash *t) {
  tuplehash u;
  if (th_init(&u, t->cap, t->klen)) return 1;
  for (size_t i = 0; i < t->cap; i++) {
    if (t->e[i].val < 0) continue;
    size_t h = th_hash(t->e[i].k, t->klen) & (u.cap - 1);
    while (u.e[h].val >= 0) h = (h + 1) & (u.cap - 1);
    u.e[h] = t->e[i];
    u.n++;
  }
  free(t->e);
  *t = u;
  return 0;
}

/* find the sorted key; if absent and val >= 0 insert it with val. Returns the stored value
 * (or -1 when absent and not inserted, -2 on allocation failure). *found tells which. */
static inline int th_get(tuplehash *t, const int *key, int val, int *found) {
  int k[4] = {0, 0, 0, 0};
  memcpy(k, key, sizeof(int) * (size_t)t->klen);
  th_sort(k, t->klen);
  if (2 * (t->n + 1) > t->cap && th_grow(t)) return -2;
  size_t h = th_hash(k, t->klen) & (t->cap - 1);
  while (t->e[h].val >= 0) {
    if (!memcmp(t->e[h].k, k, sizeof(int) * (size_t)t->klen)) {
      if (found) *found = 1;
      return t->e[h].val;
    }
    h = (h + 1) & (t->cap - 1);
  }
  if (found) *found = 0;
  if (val < 0) return -1;
  memcpy(t->e[h].k, k, sizeof k);
  t->e[h].val = val;
  t->n++;
  return val;
}

#endif
