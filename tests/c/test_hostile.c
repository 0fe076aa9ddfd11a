/* test_hostile.c — replays tests/data/hostile/mesh/ through the fuzz target of
 * tests/fuzz/fuzz_mesh.c: every file that ever crashed, hung or was answered wrongly, with
 * the answer it must get now (EXPECT: "FILE error TEXT" for a message that must contain
 * TEXT, "FILE ok key=value ..." for a mesh that must be read with those properties); files
 * without an EXPECT line (fuzzer reproducers) must simply run through), and every input
 * of tests/data/hostile/expr and tests/data/hostile/untangle through the expression and
 * untangler targets (the targets check their own invariants and abort on a broken one). */
#include "../fuzz/fuzz_expr.c"
#include "../fuzz/fuzz_mesh.c"
#include "../fuzz/fuzz_untangle.c"

#include "check.h"

#include <dirent.h>

static char *slurp(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 1 << 16, n = 0;
  char *b = malloc(cap);
  for (size_t got; b && (got = fread(b + n, 1, cap - n, f)) > 0;) {
    n += got;
    if (n == cap) { char *nb = realloc(b, cap *= 2); if (!nb) { free(b); b = NULL; } else b = nb; }
  }
  fclose(f);
  *len = n;
  return b;
}

/* "key=value" checks against a result */
static int check_props(const char *file, const fuzz_mesh_result *r, char *props) {
  int bad = 0;
  for (char *kv = strtok(props, " \t"); kv; kv = strtok(NULL, " \t")) {
    char *eq = strchr(kv, '=');
    if (!eq) { printf("  %s: bad EXPECT entry %s\n", file, kv); bad = 1; continue; }
    *eq = 0;
    const char *k = kv, *v = eq + 1;
    double want = atof(v), got = NAN;
    if (!strcmp(k, "cells")) got = r->ncell;
    else if (!strcmp(k, "vertices")) got = r->nvert;
    else if (!strcmp(k, "bfacets")) got = r->nbf;
    else if (!strcmp(k, "invalid")) got = r->ninvalid;
    else if (!strcmp(k, "qmin")) got = r->mean_ratio_min;
    else if (!strcmp(k, "name") || !strcmp(k, "region")) { /* ~ stands for a space */
      char quoted[300];
      snprintf(quoted, sizeof quoted, "\"%s\"", v);
      for (char *p = quoted; *p; p++)
        if (*p == '~') *p = ' ';
      const char *list = k[0] == 'n' ? r->names : r->rnames;
      if (!strstr(list, quoted)) { printf("  %s: %s name %s missing (names: %s)\n", file, k, quoted, list); bad = 1; }
      continue;
    } else { printf("  %s: unknown EXPECT key %s\n", file, k); bad = 1; continue; }
    double tol = !strcmp(k, "qmin") ? 1e-9 : 0;
    if (!(fabs(got - want) <= tol * (1 + fabs(want)))) { printf("  %s: %s = %.17g, expected %s\n", file, k, got, v); bad = 1; }
  }
  return bad;
}

int main(int argc, char **argv) {
  char dir[512], path[1024], line[2048];
  snprintf(dir, sizeof dir, "%s/hostile/mesh", argc > 1 ? argv[1] : "tests/data");
  snprintf(path, sizeof path, "%s/EXPECT", dir);
  FILE *ex = fopen(path, "r");
  CHECK(ex != NULL, "cannot open %s", path);
  int nexp = 0;
  char seen[512][96];
  while (ex && fgets(line, sizeof line, ex)) {
    line[strcspn(line, "\n")] = 0;
    if (!line[0] || line[0] == '#') continue;
    char file[96], kind[16];
    int off = 0;
    if (sscanf(line, "%95s %15s %n", file, kind, &off) < 2) { CHECK(0, "bad EXPECT line: %s", line); continue; }
    char *rest = line + off;
    if (nexp < 512) snprintf(seen[nexp++], sizeof seen[0], "%s", file);
    snprintf(path, sizeof path, "%s/%s", dir, file);
    size_t len;
    char *data = slurp(path, &len);
    CHECK(data != NULL, "cannot read %s", path);
    if (!data) continue;
    fuzz_mesh_result r;
    fuzz_mesh_run((const uint8_t *)data, len, &r);
    free(data);
    if (getenv("LUGAL_HOSTILE_SHOW")) /* to write EXPECT lines */
      printf("%-28s %s\n", file, r.ok ? "" : r.err),
      r.ok && printf("    cells=%d vertices=%d bfacets=%d invalid=%d qmin=%.17g names=%s\n", r.ncell, r.nvert, r.nbf,
                     r.ninvalid, r.mean_ratio_min, r.names);
    if (!strcmp(kind, "error")) {
      CHECK(!r.ok, "%s: read without an error, expected one containing \"%s\"", file, rest);
      CHECK(r.ok || strstr(r.err, rest), "%s: the message \"%s\" does not contain \"%s\"", file, r.err, rest);
    } else if (!strcmp(kind, "ok")) {
      CHECK(r.ok, "%s: refused: %s", file, r.err);
      if (r.ok) CHECK(!check_props(file, &r, rest), "%s: properties", file);
    } else {
      CHECK(0, "bad EXPECT kind %s", kind);
    }
  }
  if (ex) fclose(ex);
  /* reproducers without expectations: they must run through */
  DIR *d = opendir(dir);
  int nrepro = 0;
  for (struct dirent *de; d && (de = readdir(d));) {
    if (de->d_name[0] == '.' || !strcmp(de->d_name, "EXPECT")) continue;
    int listed = 0;
    for (int i = 0; i < nexp && !listed; i++) listed = !strcmp(seen[i], de->d_name);
    if (listed) continue;
    snprintf(path, sizeof path, "%s/%s", dir, de->d_name);
    size_t len;
    char *data = slurp(path, &len);
    if (!data) continue;
    fuzz_mesh_result r;
    fuzz_mesh_run((const uint8_t *)data, len, &r);
    free(data);
    nrepro++;
  }
  if (d) closedir(d);
  printf("%d hostile meshes with expectations, %d reproducers\n", nexp, nrepro);
  static const char *other[] = {"expr", "untangle"};
  for (int k = 0; k < 2; k++) {
    snprintf(dir, sizeof dir, "%s/hostile/%s", argc > 1 ? argv[1] : "tests/data", other[k]);
    DIR *od = opendir(dir);
    int cnt = 0;
    for (struct dirent *de; od && (de = readdir(od));) {
      if (de->d_name[0] == '.') continue;
      snprintf(path, sizeof path, "%s/%s", dir, de->d_name);
      size_t len;
      char *data = slurp(path, &len);
      if (!data) continue;
      if (k == 0) fuzz_expr_run((const uint8_t *)data, len);
      else fuzz_untangle_run((const uint8_t *)data, len);
      free(data);
      cnt++;
    }
    if (od) closedir(od);
    printf("%d %s inputs\n", cnt, other[k]);
  }
  return CHECK_DONE();
}
