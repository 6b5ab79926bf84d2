/* rfverify's driver of Siconos GRFC3D_IPM (issue 30) and GFC3D_IPM (issue 51): read a problem in rfverify's binary exchange
 * format, call global_rolling_friction_3d_driver with GRFC3D_IPM at a given tolerance and iteration
 * limit, and write the answer in the original variables.
 *
 *   rfverify-siconos-driver IN OUT [--verbose]
 *
 * IN (little endian; written by rfverify.solver.siconos_peer):
 *   char[8] "RFVSIC01"; int64 m, n, nnz(M), nnz(H), max_iter; double tol;
 *   M  (m x m, CSC): int64 colptr[m+1], int64 rowind[nnz(M)], double val[nnz(M)];
 *   H  (m x 5n, CSC; u = H^T v + w, M v = H r + f): int64 colptr[5n+1], rowind, val;
 *   double f[m], w[5n], mu[n], mu_r[n].
 * OUT: char[8] "RFVSOL01"; int64 info, iterations; double residual (Siconos's own, in its scaled
 *   variables), projection error, seconds (wall clock of the solver call);
 *   double v[m], u[5n], r[5n] (original variables: u = P^-1 u_s, r = P r_s with
 *   P = diag(1, mu, mu, mu_r, mu_r) per contact), u_s[5n], r_s[5n] (as GRFC3D_IPM returned them).
 *
 * Second mode (issue 51), chosen by the input's magic: the 3-D global Coulomb problem, solved by
 * gfc3d_driver with GFC3D_IPM (Siconos's defaults: De Saxce's shift updated inside the iterations,
 * SICONOS_FRICTION_3D_IPM_IPARAM_UPDATE_S_INTERNAL) at a given tolerance and iteration limit.
 * IN:  char[8] "RFVGFC01"; int64 m, n, nnz(M), nnz(H), max_iter; double tol;
 *   M (m x m, CSC), H (m x 3n, CSC) as above; double f[m], w[3n], mu[n].
 * OUT: char[8] "RFVGSO01"; int64 info, iterations; double residual (Siconos's own), seconds;
 *   double v[m], u[3n], r[3n] as GFC3D_IPM returned them (it converts back to the original
 *   variables itself; u is its modified velocity u + mu|u_T| e_N of its last iterate).
 *
 * The matrices are handed over directly, not through Siconos's FCLIB reader (see README.md beside).
 * Test-only: with RFVERIFY_SICONOS_FAULT=sigsegv in the environment the driver raises SIGSEGV
 * after reading its input, so that tests can check that a crash is recorded as a failure.
 * Exit codes: 0 answer written (whatever Siconos's info), 2 bad input/usage, 3 out of memory/IO.
 */
#define _POSIX_C_SOURCE 200809L
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "CSparseMatrix.h"
#include "GlobalFrictionContactProblem.h"
#include "GlobalRollingFrictionContactProblem.h"
#include "NonSmoothDrivers.h"
#include "NumericsMatrix.h"
#include "NumericsVerbose.h"
#include "SolverOptions.h"
#include "fc3d_short_names.h"
#include "rolling_friction_3d_short_names.h"

static void fail(int code, const char *what, const char *path) {
  fprintf(stderr, "rfverify-siconos-driver: %s%s%s\n", what, path ? ": " : "", path ? path : "");
  exit(code);
}

static void *xmalloc(size_t count, size_t size) {
  void *p = calloc(count ? count : 1, size);
  if (!p) fail(3, "out of memory", NULL);
  return p;
}

static void read_exact(FILE *f, void *buf, size_t size, size_t count, const char *path) {
  if (fread(buf, size, count, f) != count) fail(2, "input file truncated", path);
}

static void write_exact(FILE *f, const void *buf, size_t size, size_t count, const char *path) {
  if (fwrite(buf, size, count, f) != count) fail(3, "cannot write output", path);
}

/* A CSC NumericsMatrix (rows x cols) from int64 arrays, indices checked. */
static NumericsMatrix *read_csc(FILE *f, int64_t rows, int64_t cols, int64_t nnz, const char *path) {
  int64_t *p = xmalloc((size_t)cols + 1, sizeof(int64_t));
  int64_t *i = xmalloc((size_t)nnz, sizeof(int64_t));
  read_exact(f, p, sizeof(int64_t), (size_t)cols + 1, path);
  read_exact(f, i, sizeof(int64_t), (size_t)nnz, path);
  if (p[0] != 0 || p[cols] != nnz) fail(2, "bad CSC column pointers", path);
  for (int64_t k = 0; k < cols; ++k)
    if (p[k + 1] < p[k]) fail(2, "decreasing CSC column pointers", path);
  for (int64_t k = 0; k < nnz; ++k)
    if (i[k] < 0 || i[k] >= rows) fail(2, "CSC row index out of range", path);
  NumericsMatrix *A = NM_create(NM_SPARSE, (int)rows, (int)cols);
  NM_csc_alloc(A, (CS_INT)(nnz ? nnz : 1));
  A->matrix2->origin = NSM_CSC;
  CSparseMatrix *C = A->matrix2->csc;
  for (int64_t k = 0; k <= cols; ++k) C->p[k] = (CS_INT)p[k];
  for (int64_t k = 0; k < nnz; ++k) C->i[k] = (CS_INT)i[k];
  read_exact(f, C->x, sizeof(double), (size_t)nnz, path);
  free(p);
  free(i);
  return A;
}

static double wall(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* The input's sizes, iteration limit and tolerance (after the magic), checked; dim per contact. */
typedef struct { int64_t m, n, nnzM, nnzH, max_iter; double tol; } Head;

static Head read_head(FILE *f, const char *in, int64_t dim) {
  int64_t head[5];
  Head h;
  read_exact(f, head, sizeof(int64_t), 5, in);
  read_exact(f, &h.tol, sizeof(double), 1, in);
  h.m = head[0], h.n = head[1], h.nnzM = head[2], h.nnzH = head[3], h.max_iter = head[4];
  if (h.m <= 0 || h.n < 0 || h.nnzM < 0 || h.nnzH < 0 || h.max_iter < 1 || !(h.tol > 0) || h.m > INT32_MAX ||
      dim * h.n > INT32_MAX)
    fail(2, "bad sizes, tolerance or iteration limit", in);
  return h;
}

/* count doubles read into a new array. */
static double *read_doubles(FILE *f, int64_t count, const char *in) {
  double *x = xmalloc((size_t)count, sizeof(double));
  read_exact(f, x, sizeof(double), (size_t)count, in);
  return x;
}

/* The fields both problem types share, read in the input's order (M, H, f, w, mu); a macro
 * because GlobalFrictionContactProblem and GlobalRollingFrictionContactProblem are two structs. */
#define READ_SHARED_FIELDS(problem, f, h, dim, in)                   \
  do {                                                              \
    (problem)->dimension = (dim);                                   \
    (problem)->numberOfContacts = (int)(h).n;                       \
    (problem)->M = read_csc((f), (h).m, (h).m, (h).nnzM, (in));     \
    (problem)->H = read_csc((f), (h).m, (dim) * (h).n, (h).nnzH, (in)); \
    (problem)->q = read_doubles((f), (h).m, (in));                  \
    (problem)->b = read_doubles((f), (dim) * (h).n, (in));          \
    (problem)->mu = read_doubles((f), (h).n, (in));                 \
  } while (0)

/* Test-only (see the header): a crash after the input is read. */
static void maybe_fault(void) {
  const char *fault = getenv("RFVERIFY_SICONOS_FAULT");
  if (fault && strcmp(fault, "sigsegv") == 0) raise(SIGSEGV);
}

/* The solver's options: Siconos's defaults besides tol and max_iter. */
static SolverOptions *options_for(int solver, Head h, int verbose) {
  SolverOptions *options = solver_options_create(solver);
  options->dparam[SICONOS_DPARAM_TOL] = h.tol;
  options->iparam[SICONOS_IPARAM_MAX_ITER] = (int)h.max_iter;
  numerics_set_verbose(verbose);
  return options;
}

/* OUT: magic, info and iterations, nmeta doubles, then each array of its length. */
static void write_answer(const char *out, const char *magic, int info, SolverOptions *options, const double *meta,
                         size_t nmeta, double *const *arrays, const int64_t *lengths, int count) {
  int64_t tail[2] = {info, options->iparam[SICONOS_IPARAM_ITER_DONE]};
  FILE *o = fopen(out, "wb");
  if (!o) fail(3, "cannot open output", out);
  write_exact(o, magic, 1, 8, out);
  write_exact(o, tail, sizeof(int64_t), 2, out);
  write_exact(o, meta, sizeof(double), nmeta, out);
  for (int k = 0; k < count; ++k) write_exact(o, arrays[k], sizeof(double), (size_t)lengths[k], out);
  if (fclose(o) != 0) fail(3, "cannot write output", out);
}

/* The 3-D global Coulomb problem by GFC3D_IPM (second mode, see the header); f is past the magic. */
static int solve_gfc3d(FILE *f, const char *in, const char *out, int verbose) {
  Head h = read_head(f, in, 3);
  int64_t m = h.m, n = h.n, nd = 3 * n;
  GlobalFrictionContactProblem *problem = globalFrictionContactProblem_new();
  READ_SHARED_FIELDS(problem, f, h, 3, in);
  fclose(f);
  for (int64_t c = 0; c < n; ++c) /* its change of variables P = diag(1, mu, mu) is inverted */
    if (!(problem->mu[c] > 0)) fail(2, "GFC3D_IPM needs mu > 0 on every contact", in);
  maybe_fault();

  double *v = xmalloc((size_t)m, sizeof(double));
  double *u = xmalloc((size_t)nd, sizeof(double));
  double *r = xmalloc((size_t)nd, sizeof(double));
  SolverOptions *options = options_for(GFC3D_IPM, h, verbose);

  double t0 = wall();
  int info = gfc3d_driver(problem, r, u, v, options);
  double seconds = wall() - t0;
  fflush(stdout);

  double meta[2] = {options->dparam[SICONOS_DPARAM_RESIDU], seconds};
  double *const arrays[3] = {v, u, r};
  const int64_t lengths[3] = {m, nd, nd};
  write_answer(out, "RFVGSO01", info, options, meta, 2, arrays, lengths, 3);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 3 || argc > 4 || (argc == 4 && strcmp(argv[3], "--verbose") != 0))
    fail(2, "usage: rfverify-siconos-driver IN OUT [--verbose]", NULL);
  const char *in = argv[1], *out = argv[2];
  int verbose = argc == 4;

  FILE *f = fopen(in, "rb");
  if (!f) fail(2, "cannot open input", in);
  char magic[8];
  read_exact(f, magic, 1, 8, in);
  if (memcmp(magic, "RFVGFC01", 8) == 0) return solve_gfc3d(f, in, out, verbose);
  if (memcmp(magic, "RFVSIC01", 8) != 0) fail(2, "not an rfverify Siconos input (magic)", in);
  Head h = read_head(f, in, 5);
  int64_t m = h.m, n = h.n, nd = 5 * n;

  GlobalRollingFrictionContactProblem *problem = globalRollingFrictionContactProblem_new();
  READ_SHARED_FIELDS(problem, f, h, 5, in);
  problem->mu_r = read_doubles(f, n, in);
  fclose(f);
  for (int64_t c = 0; c < n; ++c)  /* its change of variables divides by mu and mu_r */
    if (!(problem->mu[c] > 0) || !(problem->mu_r[c] > 0))
      fail(2, "GRFC3D_IPM needs mu > 0 and mu_r > 0 on every contact", in);
  maybe_fault();

  double *v = xmalloc((size_t)m, sizeof(double));
  double *u_s = xmalloc((size_t)nd, sizeof(double));
  double *r_s = xmalloc((size_t)nd, sizeof(double));
  SolverOptions *options = options_for(GRFC3D_IPM, h, verbose);

  /* Siconos prints its log on stdout; the answer goes to OUT only. */
  double t0 = wall();
  int info = global_rolling_friction_3d_driver(problem, r_s, u_s, v, options);
  double seconds = wall() - t0;
  fflush(stdout);

  /* after the solve GRFC3D_IPM leaves its projection error in solverData (one double) */
  double projerr = options->solverData ? *(double *)options->solverData : -1.0;
  double meta[3] = {options->dparam[SICONOS_DPARAM_RESIDU], projerr, seconds};

  double *u = xmalloc((size_t)nd, sizeof(double));
  double *r = xmalloc((size_t)nd, sizeof(double));
  for (int64_t k = 0; k < nd; ++k) {
    int64_t c = k / 5, j = k % 5;
    double p = j == 0 ? 1.0 : (j < 3 ? problem->mu[c] : problem->mu_r[c]);
    u[k] = u_s[k] / p;
    r[k] = r_s[k] * p;
  }

  double *const arrays[5] = {v, u, r, u_s, r_s};
  const int64_t lengths[5] = {m, nd, nd, nd, nd};
  write_answer(out, "RFVSOL01", info, options, meta, 3, arrays, lengths, 5);
  return 0;
}
