/* The installed C API from a C11 program: the Hopf scene's radius at t = 2 (as main.cpp), and
   the version the library reports (the source tree's VERSION, MOREAU_EXPECTED_VERSION). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "moreau/moreau.h"

int main(void) {
  if (strcmp(moreau_version(), MOREAU_EXPECTED_VERSION) != 0) {
    fprintf(stderr, "c_consumer: moreau_version() is %s, expected %s\n", moreau_version(),
            MOREAU_EXPECTED_VERSION);
    return 1;
  }
  moreau_scene* scene = NULL;
  moreau_run* run = NULL;
  if (moreau_scene_builtin("hopf", &scene) != MOREAU_OK ||
      moreau_run_create(scene, "radau", &run) != MOREAU_OK ||
      moreau_run_set_real(run, "h", 0.01) != MOREAU_OK || moreau_run_simulate(run) != MOREAU_OK) {
    fprintf(stderr, "c_consumer: %s\n", moreau_last_error());
    return 1;
  }
  double x[2];
  size_t n = 0;
  moreau_run_final_state(run, x, 2, &n);
  /* r(2)^2 = 1 / (1 + 3 e^{-4}) at angle 4 pi (see the scene's description). */
  const double error = fabs(x[0] - sqrt(1.0 / (1.0 + 3.0 * exp(-4.0))));
  printf("c_consumer: moreau %s, x(2) error %.3e\n", moreau_version(), error);
  moreau_run_free(run);
  moreau_scene_free(scene);
  return error < 1e-8 ? 0 : 1;
}
