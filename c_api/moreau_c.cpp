// The C API (include/moreau/moreau.h): a front end over moreau::Simulate / moreau::Simulator,
// like the command line and Python. Every entry point runs its body inside Guard, which turns
// every C++ exception into a status and the thread's last error; nothing else crosses.
#include <algorithm>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/moreau.h"
#include "moreau/scenes/catalog.hpp"
#include "moreau/version.hpp"

struct moreau_scene {
  moreau::Scene scene;
};

struct moreau_run {
  moreau::Scene scene;
  moreau::SimulationSettings settings;
  std::unique_ptr<moreau::Simulator> simulator;  // prepared at the first simulate after a change
  std::map<std::string, double> values;          // scene values for every simulation
  std::optional<moreau::SimulationResult> result;
};

namespace {

thread_local std::string last_error;

// A failure status with its message (for the thread's last error).
struct Failure {
  moreau_status status;
  std::string message;
};

template <class... Args>
[[noreturn]] void Fail(moreau_status status, const Args&... args) {
  throw Failure{status, moreau::internal::Concat(args...)};
}

template <class Body>
moreau_status Guard(Body&& body) noexcept {
  try {
    body();
    return MOREAU_OK;
  } catch (const Failure& failure) {
    last_error = failure.message;
    return failure.status;
  } catch (const std::invalid_argument& error) {
    last_error = error.what();
    return MOREAU_INVALID_ARGUMENT;
  } catch (const std::bad_alloc&) {
    last_error = "out of memory";
    return MOREAU_INTERNAL_ERROR;
  } catch (const std::exception& error) {
    last_error = std::string("internal error: ") + error.what();
    return MOREAU_INTERNAL_ERROR;
  } catch (...) {
    last_error = "internal error: unknown exception";
    return MOREAU_INTERNAL_ERROR;
  }
}

template <class T>
T& Require(T* handle, const char* what) {
  if (handle == nullptr) Fail(MOREAU_INVALID_ARGUMENT, what, " is NULL");
  return *handle;
}

std::string RequireText(const char* text, const char* what) {
  if (text == nullptr) Fail(MOREAU_INVALID_ARGUMENT, what, " is NULL");
  return text;
}

const moreau::SimulationResult& Result(const moreau_run* run) {
  const moreau_run& r = Require(run, "run");
  if (!r.result) Fail(MOREAU_NOT_AVAILABLE, "the run has no result: call moreau_run_simulate");
  return *r.result;
}

// Writes n values into out (capacity values) unless out is NULL (a size query).
void CopyOut(const double* values, std::size_t n, double* out, std::size_t capacity,
             const char* what) {
  if (out == nullptr) return;
  if (capacity < n) {
    Fail(MOREAU_BUFFER_TOO_SMALL, what, ": the array holds ", capacity, " values, ", n,
         " are needed");
  }
  if (n > 0) std::memcpy(out, values, n * sizeof(double));
}

void CopyMatrix(const moreau::Matrix& m, double* out, std::size_t capacity, std::size_t* rows,
                std::size_t* cols, const char* what) {
  if (rows != nullptr) *rows = static_cast<std::size_t>(m.rows());
  if (cols != nullptr) *cols = static_cast<std::size_t>(m.cols());
  CopyOut(m.data(), static_cast<std::size_t>(m.size()), out, capacity, what);
}

// Copies text into buffer (size bytes with the NUL) unless buffer is NULL; a text longer than
// the buffer is MOREAU_BUFFER_TOO_SMALL (nothing written).
void CopyText(const std::string& text, char* buffer, std::size_t size, std::size_t* length,
              const char* what) {
  if (length != nullptr) *length = text.size();
  if (buffer == nullptr) return;
  if (size < text.size() + 1) {
    Fail(MOREAU_BUFFER_TOO_SMALL, what, ": the buffer holds ", size, " bytes, ", text.size() + 1,
         " are needed");
  }
  std::memcpy(buffer, text.c_str(), text.size() + 1);
}

moreau_status MakeScene(moreau_scene** out, const auto& make) {
  return Guard([&] {
    moreau_scene** target = &Require(out, "scene output");
    *target = nullptr;
    auto scene = std::make_unique<moreau_scene>(moreau_scene{make()});
    *target = scene.release();
  });
}

void SetOption(moreau_run* run, const char* name, moreau::SettingValue value) {
  moreau_run& r = Require(run, "run");
  r.settings.options[RequireText(name, "option name")] = std::move(value);
  r.simulator.reset();  // checked and prepared again at the next simulate
}

}  // namespace

extern "C" {

const char* moreau_last_error(void) { return last_error.c_str(); }

const char* moreau_version(void) { return MOREAU_VERSION; }

const char* moreau_status_name(moreau_status status) {
  switch (status) {
    case MOREAU_OK:
      return "ok";
    case MOREAU_INVALID_ARGUMENT:
      return "invalid_argument";
    case MOREAU_SIMULATION_FAILED:
      return "simulation_failed";
    case MOREAU_BUFFER_TOO_SMALL:
      return "buffer_too_small";
    case MOREAU_NOT_AVAILABLE:
      return "not_available";
    case MOREAU_INTERNAL_ERROR:
      return "internal_error";
  }
  return "unknown_status";
}

moreau_status moreau_scene_builtin(const char* name, moreau_scene** scene) {
  return MakeScene(scene, [&] { return moreau::MakeScene(RequireText(name, "scene name")); });
}

moreau_status moreau_scene_load(const char* path, moreau_scene** scene) {
  return MakeScene(scene, [&] { return moreau::LoadScene(RequireText(path, "path")); });
}

moreau_status moreau_scene_parse(const char* text, const char* source_name, moreau_scene** scene) {
  return MakeScene(scene, [&] {
    return moreau::ParseScene(RequireText(text, "scene text"),
                              source_name != nullptr ? source_name : "<string>");
  });
}

void moreau_scene_free(moreau_scene* scene) { delete scene; }

moreau_status moreau_scene_sizes(const moreau_scene* scene, size_t* num_states,
                                 size_t* num_parameters, size_t* num_inputs, size_t* num_segments) {
  return Guard([&] {
    const moreau::Scene& s = Require(scene, "scene").scene;
    if (num_states != nullptr) *num_states = static_cast<std::size_t>(s.num_states());
    if (num_parameters != nullptr) *num_parameters = static_cast<std::size_t>(s.num_parameters());
    if (num_inputs != nullptr) *num_inputs = static_cast<std::size_t>(s.num_inputs());
    if (num_segments != nullptr) {
      // Control segments between t0, the breakpoints inside (t0, tf) and tf.
      std::size_t segments = 1;
      for (double t : s.ControlBreakpoints()) {
        if (t > s.initial_time && t < s.final_time) ++segments;
      }
      *num_segments = segments;
    }
  });
}

moreau_status moreau_scene_set_value(moreau_scene* scene, const char* name, double value) {
  return Guard([&] {
    moreau::Scene& s = Require(scene, "scene").scene;
    moreau::SetSceneValue(&s, RequireText(name, "value name"), value);
  });
}

moreau_status moreau_scene_state_name(const moreau_scene* scene, size_t index, char* buffer,
                                      size_t size, size_t* length) {
  return Guard([&] {
    const moreau::Scene& s = Require(scene, "scene").scene;
    if (index >= s.state_names.size()) {
      Fail(MOREAU_INVALID_ARGUMENT, "state index ", index, " is out of range (",
           s.state_names.size(), " states)");
    }
    CopyText(s.state_names[index], buffer, size, length, "state name");
  });
}

moreau_status moreau_scene_parameter_name(const moreau_scene* scene, size_t index, char* buffer,
                                          size_t size, size_t* length) {
  return Guard([&] {
    const moreau::Scene& s = Require(scene, "scene").scene;
    if (index >= s.parameters.size()) {
      Fail(MOREAU_INVALID_ARGUMENT, "parameter index ", index, " is out of range (",
           s.parameters.size(), " parameters)");
    }
    CopyText(s.parameters[index].name, buffer, size, length, "parameter name");
  });
}

moreau_status moreau_run_create(const moreau_scene* scene, const char* integrator,
                                moreau_run** run) {
  return Guard([&] {
    moreau_run** target = &Require(run, "run output");
    *target = nullptr;
    auto created = std::make_unique<moreau_run>();
    created->scene = Require(scene, "scene").scene;
    created->settings.integrator = integrator != nullptr ? integrator : "auto";
    moreau::FindIntegrator(created->settings.integrator == "auto"
                               ? moreau::AutomaticIntegrator(created->scene)
                               : created->settings.integrator);
    *target = created.release();
  });
}

void moreau_run_free(moreau_run* run) { delete run; }

moreau_status moreau_run_set_real(moreau_run* run, const char* name, double value) {
  return Guard([&] { SetOption(run, name, value); });
}

moreau_status moreau_run_set_integer(moreau_run* run, const char* name, long value) {
  return Guard([&] { SetOption(run, name, value); });
}

moreau_status moreau_run_set_bool(moreau_run* run, const char* name, int value) {
  return Guard([&] { SetOption(run, name, value != 0); });
}

moreau_status moreau_run_set_string(moreau_run* run, const char* name, const char* value) {
  return Guard([&] { SetOption(run, name, RequireText(value, "option value")); });
}

moreau_status moreau_run_set_reals(moreau_run* run, const char* name, const double* values,
                                   size_t count) {
  return Guard([&] {
    if (values == nullptr && count > 0) Fail(MOREAU_INVALID_ARGUMENT, "option values are NULL");
    SetOption(run, name,
              count == 0 ? std::vector<double>() : std::vector<double>(values, values + count));
  });
}

moreau_status moreau_run_set_value(moreau_run* run, const char* name, double value) {
  return Guard([&] {
    moreau_run& r = Require(run, "run");
    const std::string key = RequireText(name, "value name");
    moreau::Scene probe = r.scene;  // checks the name and value now
    moreau::SetSceneValue(&probe, key, value);
    r.values[key] = value;
  });
}

moreau_status moreau_run_set_initial_state(moreau_run* run, const double* x0, size_t count) {
  return Guard([&] {
    moreau_run& r = Require(run, "run");
    const std::vector<std::string>& names = r.scene.state_names;
    if (x0 == nullptr) Fail(MOREAU_INVALID_ARGUMENT, "initial state is NULL");
    if (count != names.size()) {
      Fail(MOREAU_INVALID_ARGUMENT, "initial state: expected ", names.size(), " values, got ",
           count);
    }
    moreau::Scene probe = r.scene;
    for (std::size_t i = 0; i < count; ++i) moreau::SetSceneValue(&probe, "x0." + names[i], x0[i]);
    for (std::size_t i = 0; i < count; ++i) r.values["x0." + names[i]] = x0[i];
  });
}

moreau_status moreau_run_simulate(moreau_run* run) {
  moreau_status status = Guard([&] {
    moreau_run& r = Require(run, "run");
    r.result.reset();
    if (!r.simulator) r.simulator = std::make_unique<moreau::Simulator>(r.scene, r.settings);
    const std::vector<std::pair<std::string, double>> values(r.values.begin(), r.values.end());
    r.result = r.simulator->Run(values);
    if (!r.result->success) {
      Fail(MOREAU_SIMULATION_FAILED, r.result->status, ": ", r.result->message);
    }
  });
  return status;
}

moreau_status moreau_run_outcome(const moreau_run* run, int* success, char* status,
                                 size_t status_size, char* message, size_t message_size) {
  return Guard([&] {
    const moreau::SimulationResult& result = Result(run);
    if (success != nullptr) *success = result.success ? 1 : 0;
    CopyText(result.status, status, status_size, nullptr, "status");
    CopyText(result.message, message, message_size, nullptr, "message");
  });
}

moreau_status moreau_run_final_time(const moreau_run* run, double* final_time) {
  return Guard([&] { Require(final_time, "final_time") = Result(run).final_time; });
}

moreau_status moreau_run_final_state(const moreau_run* run, double* x, size_t capacity,
                                     size_t* count) {
  return Guard([&] {
    const moreau::Vector& state = Result(run).final_state;
    if (count != nullptr) *count = static_cast<std::size_t>(state.size());
    CopyOut(state.data(), static_cast<std::size_t>(state.size()), x, capacity, "final state");
  });
}

moreau_status moreau_run_trajectory(const moreau_run* run, double* t, size_t t_capacity, double* x,
                                    size_t x_capacity, size_t* points, size_t* num_states) {
  return Guard([&] {
    const moreau::SimulationResult& result = Result(run);
    const moreau::Trajectory& trajectory = result.trajectory;
    const std::size_t n = trajectory.size();
    const std::size_t nx = static_cast<std::size_t>(result.final_state.size());
    if (points != nullptr) *points = n;
    if (num_states != nullptr) *num_states = nx;
    CopyOut(trajectory.t.data(), n, t, t_capacity, "trajectory times");
    if (x == nullptr) return;
    if (x_capacity < n * nx) {
      Fail(MOREAU_BUFFER_TOO_SMALL, "trajectory states: the array holds ", x_capacity, " values, ",
           n * nx, " are needed");
    }
    for (std::size_t k = 0; k < n; ++k) {
      std::copy_n(trajectory.x[k].data(), nx, x + k * nx);
    }
  });
}

moreau_status moreau_run_num_events(const moreau_run* run, size_t* count) {
  return Guard([&] { Require(count, "count") = Result(run).events.size(); });
}

moreau_status moreau_run_event(const moreau_run* run, size_t index, double* t, char* kind,
                               size_t kind_size, char* what, size_t what_size) {
  return Guard([&] {
    const std::vector<moreau::Event>& events = Result(run).events;
    if (index >= events.size()) {
      Fail(MOREAU_INVALID_ARGUMENT, "event index ", index, " is out of range (", events.size(),
           " events)");
    }
    const moreau::Event& event = events[index];
    if (t != nullptr) *t = event.t;
    CopyText(moreau::ToString(event.kind), kind, kind_size, nullptr, "event kind");
    CopyText(event.what, what, what_size, nullptr, "event what");
  });
}

moreau_status moreau_run_stat(const moreau_run* run, const char* name, double* value) {
  return Guard(
      [&] { Require(value, "value") = Result(run).Stat(RequireText(name, "statistic name")); });
}

moreau_status moreau_run_sensitivities(const moreau_run* run, double* dx_dtheta, size_t capacity,
                                       size_t* rows, size_t* cols) {
  return Guard([&] {
    const auto& s = Result(run).sensitivities;
    if (!s || s->initial_state.size() == 0) {
      Fail(MOREAU_NOT_AVAILABLE, "no full sensitivities: set the option \"sensitivities\"");
    }
    moreau::Matrix full(s->initial_state.rows(),
                        s->initial_state.cols() + s->parameters.cols() + s->inputs.cols());
    full << s->initial_state, s->parameters, s->inputs;
    CopyMatrix(full, dx_dtheta, capacity, rows, cols, "sensitivities");
  });
}

moreau_status moreau_run_directional(const moreau_run* run, double* out, size_t capacity,
                                     size_t* rows, size_t* cols) {
  return Guard([&] {
    const auto& s = Result(run).sensitivities;
    if (!s || s->directional.size() == 0) {
      Fail(MOREAU_NOT_AVAILABLE, "no directional sensitivities: set the option \"directions\"");
    }
    CopyMatrix(s->directional, out, capacity, rows, cols, "directional sensitivities");
  });
}

moreau_status moreau_run_adjoint(const moreau_run* run, double* out, size_t capacity, size_t* rows,
                                 size_t* cols) {
  return Guard([&] {
    const auto& s = Result(run).sensitivities;
    if (!s || s->adjoint.size() == 0) {
      Fail(MOREAU_NOT_AVAILABLE,
           "no adjoint sensitivities: set the option \"adjoint_weights\" or "
           "\"adjoint_sample_weights\"");
    }
    CopyMatrix(s->adjoint, out, capacity, rows, cols, "adjoint sensitivities");
  });
}

moreau_status moreau_run_sample_states(const moreau_run* run, double* out, size_t capacity,
                                       size_t* rows, size_t* cols) {
  return Guard([&] {
    const moreau::SimulationResult& result = Result(run);
    const std::size_t nx = static_cast<std::size_t>(result.final_state.size());
    moreau::Matrix states(static_cast<Eigen::Index>(nx),
                          static_cast<Eigen::Index>(result.sample_states.size()));
    for (std::size_t j = 0; j < result.sample_states.size(); ++j) {
      states.col(static_cast<Eigen::Index>(j)) = result.sample_states[j];
    }
    CopyMatrix(states, out, capacity, rows, cols, "sample states");
  });
}

moreau_status moreau_run_adjoint_sweep(const moreau_run* run, const double* final_weights,
                                       const double* sample_weights, size_t q, double* out,
                                       size_t capacity, size_t* rows, size_t* cols) {
  moreau_status status = Guard([&] {
    const moreau::SimulationResult& result = Result(run);
    if (!result.adjoint) {
      Fail(MOREAU_NOT_AVAILABLE, "the run keeps no adjoint sweep: set the option \"keep_adjoint\"");
    }
    if (q == 0) Fail(MOREAU_INVALID_ARGUMENT, "adjoint sweep: q must be at least 1");
    if (final_weights == nullptr && sample_weights == nullptr) {
      Fail(MOREAU_INVALID_ARGUMENT, "adjoint sweep: no weights (final or sample) given");
    }
    const auto nx = static_cast<Eigen::Index>(result.final_state.size());
    const auto qi = static_cast<Eigen::Index>(q);
    const auto samples = static_cast<Eigen::Index>(result.sample_states.size());
    moreau::Matrix final_matrix, sample_matrix;
    if (final_weights != nullptr) {
      final_matrix = Eigen::Map<const moreau::Matrix>(final_weights, nx, qi);
    }
    if (sample_weights != nullptr) {
      if (samples == 0) Fail(MOREAU_INVALID_ARGUMENT, "sample weights given, but no sample_times");
      sample_matrix = Eigen::Map<const moreau::Matrix>(sample_weights, nx, qi * samples);
    }
    const moreau::AdjointGradient gradient = result.adjoint->Gradient(final_matrix, sample_matrix);
    if (!gradient.success) Fail(MOREAU_SIMULATION_FAILED, "adjoint sweep: ", gradient.message);
    CopyMatrix(gradient.theta, out, capacity, rows, cols, "adjoint gradient");
  });
  return status;
}

}  // extern "C"
