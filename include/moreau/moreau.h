/* SPDX: part of moreau. The C API (C11): moreau from C, Fortran, Julia or any FFI. */
#ifndef MOREAU_MOREAU_H_
#define MOREAU_MOREAU_H_

/// @file
/// The C API of moreau: scenes and runs as opaque handles, options by name and value,
/// status codes with a thread-local last-error message, and every result written into arrays
/// the caller owns (docs/c-api.md).
///
/// Conventions:
///  - Every function that can fail returns a moreau_status. On failure it stores a message
///    in the calling thread's last error (moreau_last_error); no C++ exception, type or abort
///    crosses this interface (bad handles, names, sizes and values are statuses).
///  - Arrays are caller-owned. A function that writes an array takes its capacity (number of
///    doubles) and reports the size it needs through out-parameters. Passing a NULL array
///    (capacity 0) queries the size only and returns MOREAU_OK; a non-NULL array that is too
///    small returns MOREAU_BUFFER_TOO_SMALL and writes nothing.
///  - Matrices are stored column-major (Fortran and Julia order): entry (i, j) of an
///    r x c matrix is a[i + j r].
///  - Strings returned by the library (moreau_last_error, moreau_version) stay valid until the
///    next call on the same thread; strings copied into caller buffers are NUL-terminated.
///  - theta = (x0, p, u_1, ..., u_S) orders the data of sensitivities: the scene's initial
///    state (n_x), its parameters (n_p), then the inputs (n_u) of every control segment.
///  - Handles are not thread-safe; distinct handles may be used from distinct threads.

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Outcome of a call.
typedef enum moreau_status {
  MOREAU_OK = 0,                 ///< success
  MOREAU_INVALID_ARGUMENT = 1,   ///< bad handle, name, value, size or scene (see the message)
  MOREAU_SIMULATION_FAILED = 2,  ///< the run ended with a numerical failure (status, message)
  MOREAU_BUFFER_TOO_SMALL = 3,   ///< an output array's capacity is below the size it needs
  MOREAU_NOT_AVAILABLE = 4,      ///< the result has no such data (not requested, or no run yet)
  MOREAU_INTERNAL_ERROR = 5,     ///< an unexpected error (out of memory, a bug): see the message
} moreau_status;

/// A scene: states, initial values, horizon, parameters, inputs, dynamics and effects.
typedef struct moreau_scene moreau_scene;
/// A run: an integrator with its options bound to a copy of a scene, simulated any number of
/// times (with other initial states and parameter values), and its last result.
typedef struct moreau_run moreau_run;

/// The calling thread's last error message ("" if none). Valid until the next failing call
/// on this thread.
const char* moreau_last_error(void);

/// The library version, "major.minor.patch" (MOREAU_VERSION of moreau/version.hpp, as
/// `moreau --version` shows it).
const char* moreau_version(void);

/// The name of a status ("ok", "invalid_argument", ...); never NULL.
const char* moreau_status_name(moreau_status status);

/* --- scenes ------------------------------------------------------------------------------ */

/// A built-in scene by name (the command line's `moreau list`), e.g. "F1", "S4", "crowd:N=100".
moreau_status moreau_scene_builtin(const char* name, moreau_scene** scene);
/// A scene file (TOML, docs/scene-files.md); errors name file:line:column.
moreau_status moreau_scene_load(const char* path, moreau_scene** scene);
/// A scene from scene-file text; source_name (may be NULL) names it in messages.
moreau_status moreau_scene_parse(const char* text, const char* source_name, moreau_scene** scene);
/// Releases a scene (NULL is ignored). Runs made from it keep their own copy.
void moreau_scene_free(moreau_scene* scene);
/// Sizes: states n_x, parameters n_p, inputs n_u and control segments S (any may be NULL).
moreau_status moreau_scene_sizes(const moreau_scene* scene, size_t* num_states,
                                 size_t* num_parameters, size_t* num_inputs, size_t* num_segments);
/// Sets a named value as the command line's --set does: "tf", "x0.<state>" or a parameter.
moreau_status moreau_scene_set_value(moreau_scene* scene, const char* name, double value);
/// Copies the name of state `index` (0-based) into buffer (size bytes with the NUL);
/// *length (may be NULL) receives the name's length without the NUL.
moreau_status moreau_scene_state_name(const moreau_scene* scene, size_t index, char* buffer,
                                      size_t size, size_t* length);
/// Copies the name of parameter `index` likewise.
moreau_status moreau_scene_parameter_name(const moreau_scene* scene, size_t index, char* buffer,
                                          size_t size, size_t* length);

/* --- runs -------------------------------------------------------------------------------- */

/// A run of `scene` (copied) with `integrator` ("auto", "fesd", "timestepping", "ida",
/// "radau", "alpha"; NULL: "auto"). Options keep their declared defaults until set.
moreau_status moreau_run_create(const moreau_scene* scene, const char* integrator,
                                moreau_run** run);
/// Releases a run and its results (NULL is ignored).
void moreau_run_free(moreau_run* run);

/// Sets a real option by name, e.g. "h" (`moreau options` lists every integrator's options).
/// Options are checked at the next moreau_run_simulate: an unknown name or a bad value is
/// MOREAU_INVALID_ARGUMENT there.
moreau_status moreau_run_set_real(moreau_run* run, const char* name, double value);
/// Sets an integer option by name, e.g. "stages" (checked as moreau_run_set_real's).
moreau_status moreau_run_set_integer(moreau_run* run, const char* name, long value);
/// Sets a boolean option by name (value 0 or 1), e.g. "sensitivities".
moreau_status moreau_run_set_bool(moreau_run* run, const char* name, int value);
/// Sets an option from text: a named choice ("switching" = "heaviside") or any value as the
/// command line spells it ("0.05", "true", a list "0.1,0.2").
moreau_status moreau_run_set_string(moreau_run* run, const char* name, const char* value);
/// Sets a list option from `count` numbers, e.g. "output_times", or a matrix column-major
/// ("directions", "adjoint_weights").
moreau_status moreau_run_set_reals(moreau_run* run, const char* name, const double* values,
                                   size_t count);

/// Sets a scene value for the next simulations, named as in moreau_scene_set_value.
moreau_status moreau_run_set_value(moreau_run* run, const char* name, double value);
/// Sets the initial state for the next simulations (count = n_x values).
moreau_status moreau_run_set_initial_state(moreau_run* run, const double* x0, size_t count);

/// Simulates. MOREAU_OK on success; MOREAU_SIMULATION_FAILED if the integrator stopped with a
/// numerical failure (the result up to there is kept: status, message, trajectory);
/// MOREAU_INVALID_ARGUMENT for bad options or values (no result). The first call (and the
/// first after an option changed) checks the options and prepares the integrator (FESD
/// lowers the scene); later calls reuse it.
moreau_status moreau_run_simulate(moreau_run* run);

/* --- results of the last simulation ------------------------------------------------------ */

/// Whether it succeeded (*success 1 or 0) and its status name and message (copied into the
/// buffers like moreau_scene_state_name; either buffer may be NULL).
moreau_status moreau_run_outcome(const moreau_run* run, int* success, char* status,
                                 size_t status_size, char* message, size_t message_size);
/// The final time reached.
moreau_status moreau_run_final_time(const moreau_run* run, double* final_time);
/// The final scene state: n_x values.
moreau_status moreau_run_final_state(const moreau_run* run, double* x, size_t capacity,
                                     size_t* count);
/// The trajectory: *points times into t (capacity points) and the states, column-major
/// n_x x points, into x (capacity n_x points). Either array may be NULL.
moreau_status moreau_run_trajectory(const moreau_run* run, double* t, size_t t_capacity, double* x,
                                    size_t x_capacity, size_t* points, size_t* num_states);
/// Number of events (switches, contacts, relay jumps).
moreau_status moreau_run_num_events(const moreau_run* run, size_t* count);
/// Event `index`: its time, and its kind ("switch", "enter", ...) and what it concerns copied
/// into the buffers (either may be NULL).
moreau_status moreau_run_event(const moreau_run* run, size_t index, double* t, char* kind,
                               size_t kind_size, char* what, size_t what_size);
/// A statistic by name (`num_steps`, `num_newton_iterations`, `cpu_seconds`, ...).
moreau_status moreau_run_stat(const moreau_run* run, const char* name, double* value);

/// Full sensitivities (option "sensitivities" = true): dx(T)/dtheta, n_x x n_theta,
/// column-major (the columns: x0, then p, then u per segment).
moreau_status moreau_run_sensitivities(const moreau_run* run, double* dx_dtheta, size_t capacity,
                                       size_t* rows, size_t* cols);
/// Directional sensitivities (option "directions" = V, n_theta x k column-major):
/// dx(T)/dtheta V, n_x x k.
moreau_status moreau_run_directional(const moreau_run* run, double* out, size_t capacity,
                                     size_t* rows, size_t* cols);
/// Adjoint sensitivities (options "adjoint_weights" = W, n_x x q, and
/// "adjoint_sample_weights"): W^T dx(T)/dtheta + sample terms, q x n_theta.
moreau_status moreau_run_adjoint(const moreau_run* run, double* out, size_t capacity, size_t* rows,
                                 size_t* cols);
/// The scene states at the option "sample_times": n_x x K, column-major.
moreau_status moreau_run_sample_states(const moreau_run* run, double* out, size_t capacity,
                                       size_t* rows, size_t* cols);
/// A reverse sweep of the last run for weights chosen after it (option "keep_adjoint" =
/// true): final_weights n_x x q (NULL: zero), sample_weights n_x x (q K) for the K sample
/// times (NULL: zero); writes the q x n_theta gradients. MOREAU_SIMULATION_FAILED if a
/// Jacobian was singular at a checkpoint.
moreau_status moreau_run_adjoint_sweep(const moreau_run* run, const double* final_weights,
                                       const double* sample_weights, size_t q, double* out,
                                       size_t capacity, size_t* rows, size_t* cols);

#ifdef __cplusplus
}
#endif

#endif /* MOREAU_MOREAU_H_ */
