// moreau._moreau: the compiled half of the Python package (python/moreau/ is the other half).
// Everything goes through the library's one entry point, moreau::Simulate, and the options
// and statistics declared once per integrator (moreau::Integrators()); nothing here names an
// integrator option. Bad input raises ValueError (std::invalid_argument); a numerical failure
// is a result with success = False.

#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <limits>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/ensemble/sweep.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"
#include "moreau/version.hpp"

namespace py = pybind11;

namespace moreau::python {
void BindView(py::module_& m);  // view.cpp
namespace {

// A front end's keyword value as a SettingValue (bool before int: Python's bool is an int).
SettingValue ToSetting(const std::string& name, const py::handle& value) {
  if (py::isinstance<py::bool_>(value)) return value.cast<bool>();
  if (py::isinstance<py::int_>(value)) {
    try {
      return value.cast<long>();
    } catch (const py::cast_error&) {
      ThrowInvalidArgument("option '", name, "': integer ", py::str(value).cast<std::string>(),
                           " is out of range");
    }
  }
  if (py::isinstance<py::float_>(value)) return value.cast<double>();
  if (py::isinstance<py::str>(value)) return value.cast<std::string>();
  // numpy scalars, lists and arrays of numbers
  const py::module_ numpy = py::module_::import("numpy");
  if (py::isinstance(value, numpy.attr("integer"))) return value.cast<long>();
  if (py::isinstance(value, numpy.attr("floating"))) return value.cast<double>();
  // A 2-D array (a block of directions or weights, one column each) is read column by column,
  // the order the options document.
  if (py::isinstance<py::array>(value) && value.attr("ndim").cast<int>() == 2) {
    return ToSetting(name, value.attr("flatten")("F"));
  }
  if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value) ||
      py::isinstance<py::array>(value)) {
    std::vector<double> list;
    for (const py::handle item : value) {
      RequireArgument(py::isinstance<py::int_>(item) || py::isinstance<py::float_>(item) ||
                          py::isinstance(item, numpy.attr("number")),
                      "option '", name, "': expected a list of numbers, got an item of type ",
                      py::str(item.get_type().attr("__name__")).cast<std::string>());
      list.push_back(item.cast<double>());
    }
    return list;
  }
  ThrowInvalidArgument("option '", name, "': expected a number, bool, string or list of numbers, ",
                       "got a value of type ",
                       py::str(value.get_type().attr("__name__")).cast<std::string>());
}

// Settings from Python keywords. Python values come typed: a string is accepted for a choice
// option only ("stewart"), never parsed as a number or a bool as the command line's text is
// (h="0.1" and sensitivities="no" raise ValueError, as the docs promise).
SimulationSettings Settings(const Scene& scene, const std::string& integrator,
                            const py::dict& options) {
  SimulationSettings settings;
  settings.integrator = integrator;
  const std::string resolved = integrator == "auto" ? AutomaticIntegrator(scene) : integrator;
  const IntegratorSpec& spec = FindIntegrator(resolved);
  for (const auto& [key, value] : options) {
    const std::string name = py::str(key).cast<std::string>();
    SettingValue setting = ToSetting(name, value);
    const OptionSpec* option = spec.FindOption(name);
    if (option != nullptr && option->type != OptionSpec::Type::kChoice &&
        std::holds_alternative<std::string>(setting)) {
      const char* expected = option->type == OptionSpec::Type::kBool       ? "True or False"
                             : option->type == OptionSpec::Type::kInteger  ? "an integer"
                             : option->type == OptionSpec::Type::kRealList ? "a list of numbers"
                                                                           : "a number";
      ThrowInvalidArgument("option '", name, "' expects ", expected, ", got the string '",
                           std::get<std::string>(setting), "'");
    }
    settings.options[name] = std::move(setting);
  }
  return settings;
}

py::object FromSetting(const SettingValue& value) {
  return std::visit([](const auto& v) -> py::object { return py::cast(v); }, value);
}

// Rows of a trajectory as an (N, n) array; entries missing at a point (algebraic values at t0)
// are NaN.
py::array_t<double> Rows(const std::vector<Vector>& rows, std::size_t columns) {
  py::array_t<double> array({rows.size(), columns});
  auto out = array.mutable_unchecked<2>();
  for (std::size_t k = 0; k < rows.size(); ++k) {
    for (std::size_t i = 0; i < columns; ++i) {
      const auto index = static_cast<Eigen::Index>(i);
      out(static_cast<py::ssize_t>(k), static_cast<py::ssize_t>(i)) =
          index < rows[k].size() ? rows[k][index] : std::numeric_limits<double>::quiet_NaN();
    }
  }
  return array;
}

py::dict TrajectoryDict(const Trajectory& trajectory) {
  py::dict out;
  out["t"] =
      py::array_t<double>(static_cast<py::ssize_t>(trajectory.t.size()), trajectory.t.data());
  out["x"] = Rows(trajectory.x, trajectory.state_names.size());
  out["algebraic"] = Rows(trajectory.algebraic, trajectory.algebraic_names.size());
  out["step"] =
      py::array_t<double>(static_cast<py::ssize_t>(trajectory.step.size()), trajectory.step.data());
  out["state_names"] = trajectory.state_names;
  out["algebraic_names"] = trajectory.algebraic_names;
  return out;
}

// Calls a Python progress callback from the simulation thread (GIL released around the run):
// takes the GIL for the call; an exception in the callback stops the run and is re-raised.
class ProgressBridge {
 public:
  explicit ProgressBridge(py::object callback) : callback_(std::move(callback)) {}
  ProgressCallback Callback() {
    if (callback_.is_none()) return {};
    return [this](double t) {
      py::gil_scoped_acquire acquire;
      try {
        callback_(t);
      } catch (py::error_already_set& error) {
        error_.emplace(std::move(error));
        throw std::runtime_error("progress callback raised");
      }
    };
  }
  // With the GIL held: re-raises the callback's exception, if any.
  void Rethrow() {
    if (error_) {
      py::error_already_set error = std::move(*error_);
      error_.reset();
      throw error;
    }
  }

 private:
  py::object callback_;
  std::optional<py::error_already_set> error_;
};

SimulationResult RunSimulation(const Scene& scene, const std::string& integrator,
                               const py::dict& options, const py::object& progress) {
  const SimulationSettings settings = Settings(scene, integrator, options);
  ProgressBridge bridge(progress);
  const ProgressCallback callback = bridge.Callback();
  std::optional<SimulationResult> result;
  try {
    py::gil_scoped_release release;
    result = Simulate(scene, settings, callback);
  } catch (const std::runtime_error&) {
    bridge.Rethrow();
    throw;
  }
  return std::move(*result);
}

py::dict IntegratorDict(const IntegratorSpec& spec) {
  py::dict out;
  out["name"] = spec.name;
  out["description"] = spec.description;
  out["supported_effects"] = spec.supported_effects;
  out["supports_time_scale"] = spec.supports_time_scale;
  py::list options;
  for (const OptionSpec& option : spec.options) {
    py::dict o;
    o["name"] = option.name;
    o["meaning"] = option.meaning;
    o["type"] = ToString(option.type);
    o["default"] = FromSetting(option.default_value);
    o["choices"] = option.choices;
    options.append(o);
  }
  out["options"] = options;
  py::list stats;
  for (const StatSpec& stat : spec.stats) {
    py::dict s;
    s["name"] = stat.name;
    s["meaning"] = stat.meaning;
    s["count"] = stat.count;
    stats.append(s);
  }
  out["stats"] = stats;
  out["step_unit"] = spec.step_unit;
  out["iteration_unit"] = spec.iteration_unit;
  return out;
}

// The sweep table as columns (NumPy arrays and lists) for pandas.
py::dict SweepColumns(const SweepResult& r) {
  const auto n = static_cast<py::ssize_t>(r.rows.size());
  auto matrix = [n](std::size_t columns, auto&& value) {
    py::array_t<double> array({n, static_cast<py::ssize_t>(columns)});
    auto out = array.mutable_unchecked<2>();
    for (py::ssize_t k = 0; k < n; ++k) {
      for (std::size_t c = 0; c < columns; ++c) {
        out(k, static_cast<py::ssize_t>(c)) = value(static_cast<std::size_t>(k), c);
      }
    }
    return array;
  };
  py::array_t<long> index(n), num_events(n);
  py::array_t<bool> success(n);
  py::array_t<double> final_time(n), cpu(n);
  py::list status, message;
  for (py::ssize_t k = 0; k < n; ++k) {
    const SweepRow& row = r.rows[static_cast<std::size_t>(k)];
    index.mutable_at(k) = row.index;
    num_events.mutable_at(k) = row.num_events;
    success.mutable_at(k) = row.success;
    final_time.mutable_at(k) = row.final_time;
    cpu.mutable_at(k) = row.cpu_seconds;
    status.append(row.status);
    message.append(row.message);
  }
  py::dict out;
  out["index"] = index;
  out["varied_names"] = r.varied_names;
  out["varied"] = matrix(r.varied_names.size(),
                         [&r](std::size_t k, std::size_t c) { return r.rows[k].values[c]; });
  out["status"] = status;
  out["success"] = success;
  out["message"] = message;
  out["final_time"] = final_time;
  out["state_names"] = r.state_names;
  out["final_state"] = matrix(r.state_names.size(), [&r](std::size_t k, std::size_t c) {
    return r.rows[k].final_state[static_cast<Eigen::Index>(c)];
  });
  out["num_events"] = num_events;
  out["event_times"] =
      matrix(static_cast<std::size_t>(r.num_event_times),
             [&r](std::size_t k, std::size_t c) { return r.rows[k].event_times[c]; });
  out["stat_names"] = r.stat_names;
  out["stats"] = matrix(r.stat_names.size(),
                        [&r](std::size_t k, std::size_t c) { return r.rows[k].stats[c]; });
  out["run_cpu_seconds"] = cpu;
  out["integrator"] = r.integrator;
  out["threads"] = r.threads;
  out["wall_seconds"] = r.wall_seconds;
  return out;
}

py::dict RunSweepColumns(const Scene& scene,
                         const std::vector<std::pair<std::string, std::vector<double>>>& grids,
                         const std::vector<std::string>& samples, long num_samples,
                         std::uint64_t seed, int events, const std::string& integrator,
                         const py::dict& options, int threads, const std::vector<long>& indices,
                         const py::object& progress) {
  SweepSpec spec;
  for (const auto& [name, values] : grids) spec.grids.push_back({name, values});
  for (const std::string& s : samples) spec.samples.push_back(ParseSweepSample(s));
  spec.num_samples = num_samples;
  spec.seed = seed;
  spec.num_event_times = events;
  const SimulationSettings settings = Settings(scene, integrator, options);
  SweepProgress callback;
  std::optional<py::error_already_set> error;
  std::mutex mutex;
  if (!progress.is_none()) {
    callback = [&progress, &error, &mutex](long done, long total) {
      std::lock_guard<std::mutex> lock(mutex);
      if (error) return;
      py::gil_scoped_acquire acquire;
      try {
        progress(done, total);
      } catch (py::error_already_set& e) {
        error.emplace(std::move(e));
      }
    };
  }
  std::optional<SweepResult> result;
  {
    py::gil_scoped_release release;
    result = RunSweep(scene, spec, settings, threads, indices, callback);
  }
  if (error) throw std::move(*error);
  return SweepColumns(*result);
}

}  // namespace
}  // namespace moreau::python

PYBIND11_MODULE(_moreau, m) {
  using namespace moreau;
  using namespace moreau::python;
  m.doc() = "Compiled core of the moreau package (use the `moreau` package, not this module).";
  m.attr("__version__") = MOREAU_VERSION;  // moreau.__version__ (moreau/version.hpp)

  py::class_<Scene>(m, "_Scene")
      .def(py::init<const Scene&>())
      .def_property_readonly("name", [](const Scene& s) { return s.name; })
      .def_property_readonly("description", [](const Scene& s) { return s.description; })
      .def_property_readonly("state_names", [](const Scene& s) { return s.state_names; })
      .def_property_readonly("x0", [](const Scene& s) { return Vector(s.initial_state); })
      .def_property_readonly("t0", [](const Scene& s) { return s.initial_time; })
      .def_property_readonly("tf", [](const Scene& s) { return s.final_time; })
      .def_property_readonly("parameters",
                             [](const Scene& s) {
                               py::list out;
                               for (const ParameterSpec& p : s.parameters) {
                                 out.append(py::make_tuple(p.name, p.value, p.description));
                               }
                               return out;
                             })
      .def_property_readonly(
          "inputs",
          [](const Scene& s) {
            py::list out;
            for (const InputSpec& input : s.inputs) {
              out.append(py::make_tuple(
                  input.name, input.kind == InputSpec::Kind::kControl ? "control" : "algebraic",
                  input.description));
            }
            return out;
          })
      .def_property_readonly("effects",
                             [](const Scene& s) {
                               py::list out;
                               for (const Effect& e : s.effects) {
                                 out.append(py::make_tuple(EffectKind(e), EffectName(e)));
                               }
                               return out;
                             })
      .def_property_readonly("time_scale_input", [](const Scene& s) { return s.time_scale_input; })
      .def("overridable_names", [](const Scene& s) { return OverridableNames(s); })
      .def("set_value",
           [](Scene& s, const std::string& name, double value) { SetSceneValue(&s, name, value); })
      .def("validate", [](const Scene& s) { ValidateScene(s); })
      .def("supporting_integrators", [](const Scene& s) { return IntegratorsSupporting(s); })
      .def("automatic_integrator", [](const Scene& s) { return AutomaticIntegrator(s); });

  m.def("_catalog", [] {
    py::list out;
    for (const SceneDefinition& d : SceneCatalog()) out.append(py::make_tuple(d.name, d.summary));
    return out;
  });
  m.def("_make_scene", [](const std::string& name) { return MakeScene(name); });
  m.def("_parse_scene", [](const std::string& text, const std::string& source) {
    return ParseScene(text, source);
  });
  m.def("_integrators", [] {
    py::list out;
    for (const IntegratorSpec& spec : Integrators()) out.append(IntegratorDict(spec));
    return out;
  });

  py::class_<SimulationResult>(m, "_Result")
      .def_readonly("scene", &SimulationResult::scene)
      .def_readonly("integrator", &SimulationResult::integrator)
      .def_readonly("success", &SimulationResult::success)
      .def_readonly("status", &SimulationResult::status)
      .def_readonly("message", &SimulationResult::message)
      .def_readonly("final_time", &SimulationResult::final_time)
      .def_readonly("state_names", &SimulationResult::state_names)
      .def_property_readonly("final_state",
                             [](const SimulationResult& r) { return Vector(r.final_state); })
      .def_property_readonly("final_inputs",
                             [](const SimulationResult& r) { return Vector(r.final_inputs); })
      .def_readonly("stats_summary", &SimulationResult::stats_summary)
      .def_readonly("num_steps", &SimulationResult::num_steps)
      .def_readonly("num_iterations", &SimulationResult::num_iterations)
      .def_readonly("cpu_seconds", &SimulationResult::cpu_seconds)
      .def_readonly("wall_seconds", &SimulationResult::wall_seconds)
      .def("options",
           [](const SimulationResult& r) {
             py::dict out;
             for (const auto& [name, value] : r.options) out[py::str(name)] = FromSetting(value);
             return out;
           })
      .def("stats",
           [](const SimulationResult& r) {
             // Counters as int (declared in the integrator's StatSpec), the rest as float.
             const IntegratorSpec& spec = FindIntegrator(r.integrator);
             py::dict out;
             for (std::size_t i = 0; i < r.stats.size(); ++i) {
               const bool count = i < spec.stats.size() && spec.stats[i].count;
               out[py::str(r.stats[i].first)] =
                   count ? py::object(py::int_(static_cast<long>(r.stats[i].second)))
                         : py::object(py::float_(r.stats[i].second));
             }
             return out;
           })
      .def("events",
           [](const SimulationResult& r) {
             py::list out;
             for (const Event& e : r.events) {
               out.append(py::make_tuple(e.t, ToString(e.kind), e.what, e.detail));
             }
             return out;
           })
      .def("relays",
           [](const SimulationResult& r) {
             py::list out;
             for (const RelaySignal& relay : r.relays) {
               out.append(py::make_tuple(relay.relay, relay.initial_value, relay.jump_times,
                                         relay.values));
             }
             return out;
           })
      .def("trajectory", [](const SimulationResult& r) { return TrajectoryDict(r.trajectory); })
      .def("stage_trajectory",
           [](const SimulationResult& r) { return TrajectoryDict(r.stage_trajectory); })
      .def("numerical_trajectory",
           [](const SimulationResult& r) { return TrajectoryDict(r.numerical_trajectory); })
      .def("records",
           [](const SimulationResult& r) {
             py::dict out;
             for (std::size_t c = 0; c < r.record_columns.size(); ++c) {
               py::array_t<double> column(static_cast<py::ssize_t>(r.records.size()));
               auto data = column.mutable_unchecked<1>();
               for (std::size_t k = 0; k < r.records.size(); ++k) {
                 data(static_cast<py::ssize_t>(k)) = r.records[k][c];
               }
               out[py::str(r.record_columns[c])] = column;
             }
             return out;
           })
      .def("step_sequence", [](const SimulationResult& r) { return r.step_sequence; })
      .def_readonly("warnings", &SimulationResult::warnings)
      .def_property_readonly("error_estimate",
                             [](const SimulationResult& r) -> py::object {
                               if (!r.error_estimate) return py::none();
                               return py::float_(*r.error_estimate);
                             })
      .def("sensitivities",
           [](const SimulationResult& r) -> py::object {
             if (!r.sensitivities) return py::none();
             py::dict out;
             out["dx_dx0"] = r.sensitivities->initial_state;
             out["dx_dp"] = r.sensitivities->parameters;
             out["dx_du"] = r.sensitivities->inputs;
             out["segment_starts"] = r.sensitivities->segment_starts;
             out["directional"] = r.sensitivities->directional;
             out["sample_directional"] = r.sensitivities->sample_directional;
             out["adjoint"] = r.sensitivities->adjoint;
             return out;
           })
      .def("sample_states", [](const SimulationResult& r) { return r.sample_states; })
      .def("has_adjoint", [](const SimulationResult& r) { return r.adjoint != nullptr; })
      .def("adjoint_gradient", [](const SimulationResult& r, const Matrix& final_weights,
                                  const Matrix& sample_weights) {
        RequireArgument(r.adjoint != nullptr,
                        "the result keeps no adjoint sweep: run with keep_adjoint=True");
        AdjointGradient gradient;
        {
          py::gil_scoped_release release;
          gradient = r.adjoint->Gradient(final_weights, sample_weights);
        }
        return py::make_tuple(gradient.success, gradient.message, gradient.theta,
                              gradient.cpu_seconds);
      });

  m.def("_parse_grid", [](const std::string& text) {
    const SweepGrid grid = ParseSweepGrid(text);
    return std::make_pair(grid.name, grid.values);
  });
  m.def("_sweep", &RunSweepColumns, py::arg("scene"), py::arg("grids"), py::arg("samples"),
        py::arg("num_samples"), py::arg("seed"), py::arg("events"), py::arg("integrator"),
        py::arg("options"), py::arg("threads"), py::arg("indices"), py::arg("progress"));
  py::class_<Simulator>(m, "_Simulator")
      .def(py::init([](const Scene& scene, const std::string& integrator, const py::dict& options) {
        return std::make_unique<Simulator>(scene, Settings(scene, integrator, options));
      }))
      .def_property_readonly("integrator", &Simulator::integrator)
      .def("run",
           [](Simulator& simulator, const std::vector<std::pair<std::string, double>>& values,
              const py::object& progress) {
             ProgressBridge bridge(progress);
             const ProgressCallback callback = bridge.Callback();
             std::optional<SimulationResult> result;
             try {
               py::gil_scoped_release release;
               result = simulator.Run(values, callback);
             } catch (const std::runtime_error&) {
               bridge.Rethrow();
               throw;
             }
             return std::move(*result);
           });

  m.def("_simulate", &RunSimulation, py::arg("scene"), py::arg("integrator"), py::arg("options"),
        py::arg("progress"));
  BindView(m);
}
