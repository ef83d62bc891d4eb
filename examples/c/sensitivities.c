/* moreau from C (include/moreau/moreau.h, docs/c-api.md): the oscillator F1 that switches at
 * the unit circle, simulated by FESD with full, directional and adjoint sensitivities, which
 * must agree: dx(T)/dtheta V (directional) and W^T dx(T)/dtheta (adjoint) against the products
 * with the full matrix. Then a scene from text with a sample time, a reverse sweep for weights
 * chosen after the run, and bad input, which must give statuses and messages.
 *
 *     build/release/examples/c/c_api_example          (exit status 0: every check passed)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "moreau/moreau.h"

static int failures = 0;

/* Reports a failed call with the library's message; returns 1 if the call succeeded. */
static int ok(moreau_status status, const char* what) {
  if (status == MOREAU_OK) return 1;
  fprintf(stderr, "%s: %s: %s\n", what, moreau_status_name(status), moreau_last_error());
  ++failures;
  return 0;
}

static void check(int condition, const char* what) {
  if (!condition) {
    fprintf(stderr, "check failed: %s\n", what);
    ++failures;
  }
}

/* Directional and adjoint results equal the products with the full matrix to this relative
 * accuracy: the same implicit-function-theorem solves, associated differently. */
#define PRODUCT_TOLERANCE 1e-10

static double max_abs(const double* a, size_t n) {
  double m = 0.0;
  for (size_t i = 0; i < n; ++i) m = fmax(m, fabs(a[i]));
  return m;
}

static int f1_sensitivities(void) {
  moreau_scene* scene = NULL;
  if (!ok(moreau_scene_builtin("F1", &scene), "scene F1")) return 1;
  size_t nx = 0, np = 0, nu = 0, segments = 0;
  ok(moreau_scene_sizes(scene, &nx, &np, &nu, &segments), "sizes");
  const size_t n_theta = nx + np + nu * segments; /* theta = (x0, omega) */
  moreau_run* run = NULL;
  if (!ok(moreau_run_create(scene, "fesd", &run), "run")) return 1;
  moreau_scene_free(scene); /* the run holds its own copy */

  /* Two directions V (n_theta x 2, column-major) and two adjoint weights W (n_x x 2). */
  double v[6] = {1.0, 0.0, 0.5, 0.0, 1.0, -0.25};
  double w[4] = {1.0, 0.0, 0.3, -0.7};
  ok(moreau_run_set_real(run, "h", 0.05), "h");
  ok(moreau_run_set_integer(run, "stages", 3), "stages");
  ok(moreau_run_set_bool(run, "sensitivities", 1), "sensitivities");
  ok(moreau_run_set_reals(run, "directions", v, 2 * n_theta), "directions");
  ok(moreau_run_set_reals(run, "adjoint_weights", w, 2 * nx), "adjoint weights");
  if (!ok(moreau_run_simulate(run), "simulate")) return 1;

  double x[2], t_final = 0.0;
  size_t count = 0;
  ok(moreau_run_final_state(run, x, 2, &count), "final state");
  ok(moreau_run_final_time(run, &t_final), "final time");
  printf("F1: x(%.6f) = (%.12f, %.12f)\n", t_final, x[0], x[1]);

  /* Sizes first (NULL arrays), then the values into arrays of that size. */
  size_t rows = 0, cols = 0;
  ok(moreau_run_sensitivities(run, NULL, 0, &rows, &cols), "sensitivity size");
  check(rows == nx && cols == n_theta, "dx/dtheta is n_x x n_theta");
  double* full = malloc(rows * cols * sizeof(double));
  ok(moreau_run_sensitivities(run, full, rows * cols, &rows, &cols), "sensitivities");
  double directional[4], adjoint[6];
  ok(moreau_run_directional(run, directional, 4, &rows, &cols), "directional");
  check(rows == nx && cols == 2, "directional is n_x x k");
  ok(moreau_run_adjoint(run, adjoint, 6, &rows, &cols), "adjoint");
  check(rows == 2 && cols == n_theta, "adjoint is q x n_theta");

  double error = 0.0, scale = max_abs(full, nx * n_theta);
  for (size_t i = 0; i < nx; ++i) {
    for (size_t k = 0; k < 2; ++k) {
      double product = 0.0; /* (dx/dtheta V)(i, k) */
      for (size_t j = 0; j < n_theta; ++j) product += full[i + j * nx] * v[j + k * n_theta];
      error = fmax(error, fabs(product - directional[i + k * nx]));
    }
  }
  for (size_t k = 0; k < 2; ++k) {
    for (size_t j = 0; j < n_theta; ++j) {
      double product = 0.0; /* (W^T dx/dtheta)(k, j) */
      for (size_t i = 0; i < nx; ++i) product += w[i + k * nx] * full[i + j * nx];
      error = fmax(error, fabs(product - adjoint[k + j * 2]));
    }
  }
  printf("F1: directional and adjoint against the full matrix: %.2e (relative)\n", error / scale);
  check(error <= PRODUCT_TOLERANCE * scale, "directional and adjoint equal the products");

  double steps = 0.0;
  ok(moreau_run_stat(run, "num_switches", &steps), "stat");
  check(steps >= 1.0, "F1 switches");
  size_t events = 0;
  ok(moreau_run_num_events(run, &events), "events");
  if (events > 0) {
    char kind[32], what[64];
    double t = 0.0;
    ok(moreau_run_event(run, 0, &t, kind, sizeof kind, what, sizeof what), "event");
    printf("F1: first event at t = %.12f: %s %s (the switch is at t = 1)\n", t, kind, what);
  }
  free(full);
  moreau_run_free(run);
  return 0;
}

/* A scalar function of a sample state and the final state, f = x(1)^2 + x(T), differentiated
 * by one reverse sweep after the run, against central differences in x0 (the map is smooth:
 * x' = -k x, x(t) = x0 exp(-k t)). */
static int sample_sweep(void) {
  const char* text =
      "name = \"decay\"\n"
      "states = [\"x\"]\n"
      "x0 = [2.0]\n"
      "tf = 2.0\n"
      "dynamics = [\"-k*x\"]\n"
      "[[parameters]]\n"
      "name = \"k\"\n"
      "value = 0.5\n";
  moreau_scene* scene = NULL;
  if (!ok(moreau_scene_parse(text, "decay.toml", &scene), "parse")) return 1;
  moreau_run* run = NULL;
  ok(moreau_run_create(scene, "fesd", &run), "run");
  const double sample_time = 1.0;
  ok(moreau_run_set_real(run, "h", 0.1), "h");
  ok(moreau_run_set_reals(run, "sample_times", &sample_time, 1), "sample times");
  ok(moreau_run_set_bool(run, "keep_adjoint", 1), "keep adjoint");
  if (!ok(moreau_run_simulate(run), "simulate")) return 1;
  double x_sample = 0.0, x_final = 0.0;
  size_t rows = 0, cols = 0, count = 0;
  ok(moreau_run_sample_states(run, &x_sample, 1, &rows, &cols), "sample states");
  ok(moreau_run_final_state(run, &x_final, 1, &count), "final state");
  const double final_weight = 1.0, sample_weight = 2.0 * x_sample; /* df/dx(T), df/dx(1) */
  double gradient[2];                                              /* df/dx0, df/dk */
  ok(moreau_run_adjoint_sweep(run, &final_weight, &sample_weight, 1, gradient, 2, &rows, &cols),
     "sweep");
  const double x0 = 2.0, k = 0.5;
  const double exact = 2.0 * x0 * exp(-2.0 * k * sample_time) + exp(-2.0 * k);
  printf("decay: df/dx0 = %.12f (exact flow %.12f), df/dk = %.12f\n", gradient[0], exact,
         gradient[1]);
  /* FESD's discretization error at h = 0.1, s = 3 (order 5) is far below 1e-8. */
  check(fabs(gradient[0] - exact) <= 1e-8, "df/dx0 against the exact flow");
  check(rows == 1 && cols == 2, "one gradient row over (x0, k)");
  moreau_run_free(run);
  moreau_scene_free(scene);
  return 0;
}

/* Bad input: statuses and messages, never an abort. */
static void bad_input(void) {
  moreau_scene* scene = NULL;
  moreau_status status = moreau_scene_builtin("no_such_scene", &scene);
  check(status == MOREAU_INVALID_ARGUMENT && scene == NULL, "unknown scene");
  check(strlen(moreau_last_error()) > 0, "a message for the unknown scene");
  status = moreau_scene_parse("states = [", "broken.toml", &scene);
  check(status == MOREAU_INVALID_ARGUMENT, "broken scene text");
  printf("bad input: %s\n", moreau_last_error());
  check(strstr(moreau_last_error(), "broken.toml") != NULL, "the message names the source");
  check(moreau_scene_sizes(NULL, NULL, NULL, NULL, NULL) == MOREAU_INVALID_ARGUMENT, "NULL scene");
  check(moreau_run_simulate(NULL) == MOREAU_INVALID_ARGUMENT, "NULL run");

  ok(moreau_scene_builtin("F1", &scene), "F1");
  moreau_run* run = NULL;
  check(moreau_run_create(scene, "no_such_integrator", &run) == MOREAU_INVALID_ARGUMENT,
        "unknown integrator");
  ok(moreau_run_create(scene, "fesd", &run), "run");
  double x[2];
  check(moreau_run_final_state(run, x, 2, NULL) == MOREAU_NOT_AVAILABLE, "no result yet");
  ok(moreau_run_set_real(run, "no_such_option", 1.0), "set (checked at simulate)");
  check(moreau_run_simulate(run) == MOREAU_INVALID_ARGUMENT, "unknown option");
  printf("bad input: %s\n", moreau_last_error());
  moreau_run_free(run);
  ok(moreau_run_create(scene, "fesd", &run), "run");
  ok(moreau_run_set_real(run, "h", -1.0), "set h");
  check(moreau_run_simulate(run) == MOREAU_INVALID_ARGUMENT, "negative step");
  ok(moreau_run_set_real(run, "h", 0.05), "set h");
  /* n_x = 2 (or n_y = 3 over the lowered state x1, x2, clock): 5 weights fit neither. */
  const double wrong[5] = {1.0, 2.0, 3.0, 4.0, 5.0};
  check(moreau_run_set_initial_state(run, wrong, 3) == MOREAU_INVALID_ARGUMENT,
        "initial state of the wrong size");
  printf("bad input: %s\n", moreau_last_error());
  ok(moreau_run_set_reals(run, "adjoint_weights", wrong, 5), "set weights (checked at simulate)");
  check(moreau_run_simulate(run) == MOREAU_INVALID_ARGUMENT, "weights of the wrong size");
  printf("bad input: %s\n", moreau_last_error());
  ok(moreau_run_set_reals(run, "adjoint_weights", wrong, 2), "weights");
  ok(moreau_run_simulate(run), "simulate");
  double small[1];
  size_t rows = 0, cols = 0;
  check(moreau_run_adjoint(run, small, 1, &rows, &cols) == MOREAU_BUFFER_TOO_SMALL,
        "a buffer too small");
  check(rows == 1 && cols == 3, "the size it needs");
  check(moreau_run_directional(run, NULL, 0, &rows, &cols) == MOREAU_NOT_AVAILABLE,
        "no directions requested");
  moreau_run_free(run);
  moreau_scene_free(scene);
}

int main(void) {
  printf("moreau %s\n", moreau_version());
  f1_sensitivities();
  sample_sweep();
  bad_input();
  if (failures > 0) {
    fprintf(stderr, "%d checks failed\n", failures);
    return 1;
  }
  printf("all checks passed\n");
  return 0;
}
