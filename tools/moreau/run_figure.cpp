// trajectory.png of `moreau run`: a figure built from what the scene contains (gnuplot).
//
// Left, against time (axes end at the run's final time): the states with their labels and
// units; what the effects did (multipliers of moving sets and complementarity pairs as
// piecewise-constant lines on the stage intervals, so a jump is drawn as a jump, or the number
// of active constraints when an effect has too many to read); active sets, Filippov modes and
// relay memories as bands; the events as marks in rows named by their constraint, surface or
// relay (or by kind when there are too many to name), shaped by kind. Right, for scenes with
// two states: the phase portrait with the set boundaries C(t) = {c(x, t) = 0} at the event
// times (moving sets) and the switching surfaces. Internal variables of the lowering
// (Filippov theta/lambda/mu, time-freezing variables) are left out unless asked for.
//
// The geometry of the phase panel (pixel rectangle and axis ranges) goes to figure.json, so
// that a test can check where a curve is drawn.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <variant>

#include "moreau/core/error.hpp"
#include "output.hpp"

namespace moreau::tool {

namespace {

// Figure size and panel placement in screen fractions (gnuplot "at screen").
constexpr int kFigureWidth = 1200;
constexpr int kPanelHeight = 230;  // pixels per time panel
constexpr double kTimeLeft = 0.07;
constexpr double kTimeRightWithPhase = 0.50;
constexpr double kTimeRightAlone = 0.80;
constexpr double kPhaseLeft = 0.66;
constexpr double kPhaseRight = 0.97;
// Most rows a band or event panel names one by one; more become counts or kinds.
constexpr std::size_t kMaxNamedRows = 10;
// Most events drawn as lines through the time panels (beyond: marks in the event panel only).
constexpr std::size_t kMaxEventLines = 20;
// Most multipliers drawn one by one (effects with more than kMaxNamedRows constraints get active
// counts instead).
constexpr std::size_t kMaxMultiplierLines = 8;
// Most boundary curves C(t_event) in the phase portrait (event times spread evenly).
constexpr std::size_t kMaxBoundaryTimes = 8;
// Grid of the boundary contours (marching squares on the phase panel's range).
constexpr int kContourGrid = 241;
// A constraint is active where c <= kActiveTolerance * max(1, |x|_inf): integrators put
// active constraints at c = 0 up to their Newton tolerance (1e-10 and tighter), far below.
constexpr double kActiveTolerance = 1e-7;

std::string Quote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("''") : std::string(1, c);
  return quoted + "'";
}

// Intervals [start, end) of a boolean signal on the trajectory's times.
struct Band {
  double start, end;
  int color;  // index into kBandColors
};
const char* const kBandColors[] = {"#4C78A8", "#F58518", "#54A24B", "#B279A2"};

// Bands from a state per recorded point: interval [t_k, t_{k+1}) gets the state both ends
// share; where they differ, the later end's (a switch happens at the earlier point), unless
// the later end is on a surface (2: sliding), which the earlier end then keeps. -1: no band.
std::vector<Band> Bands(const std::vector<double>& t, const std::vector<int>& state) {
  std::vector<Band> bands;
  for (std::size_t k = 0; k + 1 < t.size(); ++k) {
    const int a = state[k], b = state[k + 1];
    const int s = a == b ? a : (b != 2 ? b : a);
    if (s < 0 || !(t[k + 1] > t[k])) continue;
    if (!bands.empty() && bands.back().color == s && bands.back().end == t[k]) {
      bands.back().end = t[k + 1];
    } else {
      bands.push_back({t[k], t[k + 1], s});
    }
  }
  return bands;
}

struct BandRow {
  std::string name;
  std::vector<Band> bands;
};

// Values of an effect function along the trajectory, one vector per point.
std::vector<Vector> Along(const Scene& scene, const SmoothFunction& f, const Trajectory& traj) {
  std::vector<Vector> values(traj.size());
  const Vector p = scene.ParameterValues();
  for (std::size_t k = 0; k < traj.size(); ++k) {
    f.Evaluate(traj.x[k], scene.InputValues(traj.t[k]), traj.t[k], p, &values[k]);
  }
  return values;
}

// Marching squares for {f = 0} on a grid: segments (x1, y1, x2, y2).
std::vector<std::array<double, 4>> ZeroContour(const std::vector<double>& grid, int n, double x0,
                                               double x1, double y0, double y1) {
  std::vector<std::array<double, 4>> segments;
  auto at = [&](int i, int j) { return grid[static_cast<std::size_t>(j * n + i)]; };
  const double dx = (x1 - x0) / (n - 1), dy = (y1 - y0) / (n - 1);
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const double v[4] = {at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)};
      const double px[4] = {x0 + i * dx, x0 + (i + 1) * dx, x0 + (i + 1) * dx, x0 + i * dx};
      const double py[4] = {y0 + j * dy, y0 + j * dy, y0 + (j + 1) * dy, y0 + (j + 1) * dy};
      std::vector<std::pair<double, double>> crossings;
      for (int e = 0; e < 4; ++e) {
        const int f = (e + 1) % 4;
        if (!std::isfinite(v[e]) || !std::isfinite(v[f])) continue;
        if ((v[e] < 0.0) != (v[f] < 0.0)) {
          const double s = v[e] / (v[e] - v[f]);
          crossings.emplace_back(px[e] + s * (px[f] - px[e]), py[e] + s * (py[f] - py[e]));
        }
      }
      for (std::size_t c = 0; c + 1 < crossings.size(); c += 2) {
        segments.push_back({crossings[c].first, crossings[c].second, crossings[c + 1].first,
                            crossings[c + 1].second});
      }
    }
  }
  return segments;
}

bool IsEffectMultiplier(const Scene& scene, const std::string& column) {
  for (const Effect& effect : scene.effects) {
    std::vector<std::string> names;
    if (const auto* set = std::get_if<MovingSet>(&effect)) names = set->constraint_names;
    if (const auto* lcs = std::get_if<Complementarity>(&effect)) names = lcs->pair_names;
    for (const std::string& name : names) {
      if (column == EffectName(effect) + ".lambda_" + name) return true;
    }
  }
  return false;
}

}  // namespace

std::vector<std::string> ShownAlgebraicNames(const Scene& scene, const Trajectory& trajectory,
                                             bool internal) {
  std::vector<std::string> shown;
  for (const std::string& name : trajectory.algebraic_names) {
    if (internal || IsEffectMultiplier(scene, name)) shown.push_back(name);
  }
  return shown;
}

// The states as drawn (against time and in the phase portrait): FESD's collocation polynomials
// between the recorded points, as smooth as the run's own dense output. Error-controlled steps
// are long, and a polygon through the step points shows corners the solution does not have.
// On each element the polynomial of degree s through its start and its s Radau IIA stage points
// (c_s = 1: the last one is its end) is the collocation solution itself. Elements whose
// physical time stands still (frozen by time-freezing) and runs of other integrators keep
// their recorded points.
constexpr std::size_t kMaxCurveSamples = 4000;  // points added over the whole run, at most
constexpr std::size_t kMaxSamplesPerElement = 12;

// FESD's stages per element s if the run's stage points are whole elements of s each, else 0.
std::size_t StagesPerElement(const SimulationResult& report) {
  std::size_t s = 0;
  for (const auto& [name, value] : report.options) {
    if (name == "stages" && std::holds_alternative<long>(value)) {
      s = static_cast<std::size_t>(std::max(0L, std::get<long>(value)));
    }
  }
  const std::size_t points = report.stage_trajectory.size();
  return report.integrator == "fesd" && s > 0 && points > 0 && points % s == 0 ? s : 0;
}

Trajectory CurvePoints(const SimulationResult& report, const Trajectory& trajectory) {
  const Trajectory& stages = report.stage_trajectory;
  const std::size_t s = StagesPerElement(report);
  if (s == 0 || trajectory.size() == 0) return trajectory;
  const std::size_t elements = stages.size() / s;
  const std::size_t per_element = std::min(kMaxSamplesPerElement, kMaxCurveSamples / elements);
  Trajectory curve;
  curve.state_names = trajectory.state_names;
  double t_start = trajectory.t.front();
  Vector x_start = trajectory.x.front();
  curve.Append(t_start, x_start, Vector(), 0.0);
  std::vector<double> nodes(s + 1);  // theta of the start and the stages in [0, 1]
  for (std::size_t e = 0; e < elements; ++e) {
    const std::size_t first = e * s, last = first + s - 1;
    const double span = stages.t[last] - t_start;
    if (per_element > 0 && span > 0.5 * stages.step[last]) {
      nodes[0] = 0.0;
      for (std::size_t i = 0; i < s; ++i) nodes[i + 1] = (stages.t[first + i] - t_start) / span;
      auto node_state = [&](std::size_t i) -> const Vector& {
        return i == 0 ? x_start : stages.x[first + i - 1];
      };
      std::size_t next_stage = 0;
      for (std::size_t j = 1; j <= per_element; ++j) {
        const double theta = static_cast<double>(j) / static_cast<double>(per_element + 1);
        for (; next_stage < s && nodes[next_stage + 1] < theta; ++next_stage) {
          curve.Append(stages.t[first + next_stage], stages.x[first + next_stage], Vector(), 0.0);
        }
        Vector x = Vector::Zero(x_start.size());
        for (std::size_t i = 0; i <= s; ++i) {  // Lagrange basis L_i(theta)
          double basis = 1.0;
          for (std::size_t k = 0; k <= s; ++k) {
            if (k != i) basis *= (theta - nodes[k]) / (nodes[i] - nodes[k]);
          }
          x += basis * node_state(i);
        }
        curve.Append(t_start + theta * span, std::move(x), Vector(), 0.0);
      }
      for (; next_stage < s; ++next_stage) {
        curve.Append(stages.t[first + next_stage], stages.x[first + next_stage], Vector(), 0.0);
      }
    } else {
      for (std::size_t i = first; i <= last; ++i)
        curve.Append(stages.t[i], stages.x[i], Vector(), 0.0);
    }
    t_start = stages.t[last];
    x_start = stages.x[last];
  }
  return curve;
}

std::string WritePlot(const Scene& scene, const SimulationResult& report,
                      const Trajectory& trajectory, const std::string& directory,
                      bool numerical_time_axis, bool internal) {
  const std::string image = directory + "/trajectory.png";
  const std::string script_path = directory + "/plot.gp";
  if (trajectory.size() == 0) return "";
  const double t0 = trajectory.t.front();
  const double t_end = numerical_time_axis ? trajectory.t.back() : report.final_time;
  const auto& names = trajectory.state_names;
  const std::size_t shown = std::min<std::size_t>(names.size(), kMaxPlottedStates);

  // ---- what the effects did -------------------------------------------------------------
  // Multipliers: the stage points are the finest record; the trajectory otherwise (where each
  // value holds on the interval ending at its time).
  const Trajectory& dense = !numerical_time_axis && report.stage_trajectory.size() > 0
                                ? report.stage_trajectory
                                : trajectory;
  const std::string dense_csv =
      &dense == &trajectory ? directory + "/trajectory.csv" : directory + "/stages.csv";
  std::vector<std::pair<std::string, int>> multiplier_columns;  // name, CSV column (1-based)
  std::vector<std::string> shown_algebraic = ShownAlgebraicNames(scene, dense, internal);
  std::vector<BandRow> band_rows;
  std::vector<std::pair<std::string, std::vector<double>>> counts;  // effect, active count
  if (!numerical_time_axis) {
    for (std::size_t i = 0; i < dense.algebraic_names.size(); ++i) {
      const std::string& name = dense.algebraic_names[i];
      if (std::find(shown_algebraic.begin(), shown_algebraic.end(), name) !=
          shown_algebraic.end()) {
        multiplier_columns.push_back({name, static_cast<int>(2 + names.size() + i)});
      }
    }
    // Active sets of moving sets and modes of switching surfaces along the trajectory.
    for (const Effect& effect : scene.effects) {
      if (const auto* set = std::get_if<MovingSet>(&effect)) {
        const std::vector<Vector> c = Along(scene, set->constraints, trajectory);
        const std::size_t m = set->constraint_names.size();
        std::vector<std::vector<int>> active(m, std::vector<int>(trajectory.size(), -1));
        std::vector<double> count(trajectory.size(), 0.0);
        for (std::size_t k = 0; k < trajectory.size(); ++k) {
          const double tolerance =
              kActiveTolerance * std::max(1.0, trajectory.x[k].lpNorm<Eigen::Infinity>());
          for (std::size_t j = 0; j < m; ++j) {
            if (c[k][static_cast<Eigen::Index>(j)] <= tolerance) {
              active[j][k] = 2;  // "on the boundary": see Bands
              count[k] += 1.0;
            }
          }
        }
        if (m <= kMaxNamedRows) {
          for (std::size_t j = 0; j < m; ++j) {
            band_rows.push_back({set->name + "." + set->constraint_names[j] + " active",
                                 Bands(trajectory.t, active[j])});
          }
        } else {
          counts.push_back({set->name, count});
        }
      } else if (const auto* sw = std::get_if<SwitchingSurfaces>(&effect)) {
        const std::vector<Vector> c = Along(scene, sw->surfaces, trajectory);
        for (std::size_t j = 0; j < sw->surface_names.size() && j < kMaxNamedRows; ++j) {
          std::vector<int> side(trajectory.size());
          for (std::size_t k = 0; k < trajectory.size(); ++k) {
            const double value = c[k][static_cast<Eigen::Index>(j)];
            const double tolerance =
                kActiveTolerance * std::max(1.0, trajectory.x[k].lpNorm<Eigen::Infinity>());
            side[k] = std::abs(value) <= tolerance ? 2 : (value > 0.0 ? 1 : 0);
          }
          band_rows.push_back({sw->name + "." + sw->surface_names[j] + ": below/above/sliding",
                               Bands(trajectory.t, side)});
        }
      }
    }
    for (const RelaySignal& relay : report.relays) {
      BandRow row{relay.relay + ": w = 1", {}};
      std::vector<double> times{t0};
      times.insert(times.end(), relay.jump_times.begin(), relay.jump_times.end());
      times.push_back(t_end);
      std::vector<int> values{relay.initial_value};
      values.insert(values.end(), relay.values.begin(), relay.values.end());
      for (std::size_t k = 0; k + 1 < times.size(); ++k) {
        if (values[k] == 1 && times[k + 1] > times[k])
          row.bands.push_back({times[k], times[k + 1], 1});
      }
      band_rows.push_back(row);
    }
    if (band_rows.size() > kMaxNamedRows) band_rows.resize(kMaxNamedRows);
  }
  const bool effects_panel = !multiplier_columns.empty() || !counts.empty();
  const std::vector<Event> events = numerical_time_axis ? std::vector<Event>() : report.events;

  // Event rows: by what (constraint, surface, relay) when few, else by kind.
  std::set<std::string> whats;
  for (const Event& e : events) whats.insert(e.what);
  const bool by_what = whats.size() <= kMaxNamedRows;
  std::vector<std::string> event_rows;
  if (by_what) {
    event_rows.assign(whats.begin(), whats.end());
  } else {
    std::set<std::string> kinds;
    for (const Event& e : events) kinds.insert(ToString(e.kind));
    event_rows.assign(kinds.begin(), kinds.end());
  }
  {
    std::ofstream out(directory + "/events.dat");
    out << std::setprecision(17);
    for (const Event& e : events) {
      const std::string row = by_what ? e.what : ToString(e.kind);
      const auto index = std::find(event_rows.begin(), event_rows.end(), row) - event_rows.begin();
      out << e.t << " " << index << " " << static_cast<int>(e.kind) << "\n";
    }
  }
  if (!counts.empty()) {
    std::ofstream out(directory + "/active_counts.dat");
    out << std::setprecision(17);
    for (std::size_t k = 0; k < trajectory.size(); ++k) {
      out << trajectory.t[k];
      for (const auto& [name, count] : counts) out << " " << count[k];
      out << "\n";
    }
  }

  // ---- the states as drawn (CurvePoints) ------------------------------------------------------
  const Trajectory curve = numerical_time_axis ? trajectory : CurvePoints(report, trajectory);
  {
    std::ofstream out(directory + "/curves.dat");
    out << std::setprecision(17);
    for (std::size_t k = 0; k < curve.size(); ++k) {
      out << curve.t[k];
      // (comma-separated: the time panels read CSV)
      for (std::size_t i = 0; i < shown; ++i)
        out << "," << curve.x[k][static_cast<Eigen::Index>(i)];
      out << "\n";
    }
  }

  // ---- phase portrait -----------------------------------------------------------------------
  const bool phase = names.size() == 2;
  double range[4] = {0.0, 1.0, 0.0, 1.0};
  if (phase) {
    double lo[2] = {trajectory.x[0][0], trajectory.x[0][1]};
    double hi[2] = {lo[0], lo[1]};
    for (const Vector& x : trajectory.x) {
      for (int i = 0; i < 2; ++i) {
        lo[i] = std::min(lo[i], x[i]);
        hi[i] = std::max(hi[i], x[i]);
      }
    }
    for (int i = 0; i < 2; ++i) {
      const double pad =
          hi[i] > lo[i] ? 0.12 * (hi[i] - lo[i]) : 0.5 * std::max(1.0, std::abs(lo[i]));
      range[2 * i] = lo[i] - pad;
      range[2 * i + 1] = hi[i] + pad;
    }
    // Boundaries: moving sets at t0 and at event times, switching surfaces at t0.
    std::ofstream out(directory + "/boundaries.dat");
    out << std::setprecision(12);
    std::vector<double> times{t0};
    for (const Event& e : events) {
      if (e.kind == EventKind::kEnter || e.kind == EventKind::kLeave) times.push_back(e.t);
    }
    if (times.size() > kMaxBoundaryTimes) {
      std::vector<double> chosen;
      for (std::size_t k = 0; k < kMaxBoundaryTimes; ++k) {
        chosen.push_back(times[k * (times.size() - 1) / (kMaxBoundaryTimes - 1)]);
      }
      times = chosen;
    }
    const Vector p = scene.ParameterValues();
    for (const Effect& effect : scene.effects) {
      const SmoothFunction* f = nullptr;
      std::vector<double> at = times;
      if (const auto* set = std::get_if<MovingSet>(&effect)) f = &set->constraints;
      if (const auto* sw = std::get_if<SwitchingSurfaces>(&effect)) {
        f = &sw->surfaces;
        at = {t0};
      }
      if (f == nullptr) continue;
      for (double t : at) {
        std::vector<std::vector<double>> grids(static_cast<std::size_t>(f->num_outputs()));
        for (auto& g : grids) g.resize(static_cast<std::size_t>(kContourGrid * kContourGrid));
        Vector x(2), value;
        const Vector u = scene.InputValues(t);
        for (int j = 0; j < kContourGrid; ++j) {
          for (int i = 0; i < kContourGrid; ++i) {
            x[0] = range[0] + (range[1] - range[0]) * i / (kContourGrid - 1.0);
            x[1] = range[2] + (range[3] - range[2]) * j / (kContourGrid - 1.0);
            f->Evaluate(x, u, t, p, &value);
            for (std::size_t o = 0; o < grids.size(); ++o) {
              grids[o][static_cast<std::size_t>(j * kContourGrid + i)] =
                  value[static_cast<Eigen::Index>(o)];
            }
          }
        }
        for (const auto& grid : grids) {
          for (const auto& s :
               ZeroContour(grid, kContourGrid, range[0], range[1], range[2], range[3])) {
            out << s[0] << " " << s[1] << "\n" << s[2] << " " << s[3] << "\n\n";
          }
        }
      }
    }
  }

  // ---- the script -------------------------------------------------------------------------
  const int time_panels =
      1 + (effects_panel ? 1 : 0) + (band_rows.empty() ? 0 : 1) + (events.empty() ? 0 : 1);
  const int height = std::max(phase ? 560 : 0, 60 + kPanelHeight * time_panels);
  const double right = phase ? kTimeRightWithPhase : kTimeRightAlone;
  // Room on the left for the longest row name of the band and event panels (about 6.5 px a
  // character at 10 pt).
  std::size_t longest = 0;
  for (const BandRow& row : band_rows) longest = std::max(longest, row.name.size());
  for (const std::string& row : event_rows) longest = std::max(longest, row.size());
  const double left =
      std::clamp((6.5 * static_cast<double>(longest) + 24.0) / kFigureWidth, kTimeLeft, 0.25);
  std::ofstream s(script_path);
  RequireArgument(s.good(), "cannot write '", script_path, "'");
  s << std::setprecision(17);
  s << "set terminal pngcairo size " << kFigureWidth << "," << height
    << " noenhanced font 'sans,10'\nset output " << Quote(image)
    << "\nset datafile separator ','\nset grid\nset multiplot\n"
    << "set label 1 " << Quote(report.scene + " (" + report.integrator + ", " + report.status + ")")
    << " at screen 0.5, screen 0.985 center font 'sans,12'\n";
  const std::string time_label = numerical_time_axis ? "numerical time tau" : "t" + [&] {
    for (const auto& [state, unit] : scene.view.units) {
      if (state == "t") return " [" + unit + "]";
    }
    return std::string();
  }();
  // Panels from the top: y in screen fractions.
  const double top = 1.0 - 30.0 / height, bottom = 45.0 / height;
  const double step = (top - bottom) / time_panels;
  int panel = 0;
  auto open_panel = [&](bool last) {
    const double hi = top - panel * step, lo = hi - step;
    if (panel > 0) s << "unset label 1\n";
    s << "set lmargin at screen " << left << "\nset rmargin at screen " << right
      << "\nset tmargin at screen " << hi - 0.01 << "\nset bmargin at screen " << lo + 0.02
      << "\nset xrange [" << t0 << ":" << t_end << "]\n"
      << (last ? "set xlabel " + Quote(time_label) + "\nset format x '%g'\n"
               : "unset xlabel\nset format x ''\n")
      << "set key inside top right opaque box lc rgb '#DDDDDD' samplen 2\nunset object\n"
      << "set ytics auto\n"
      << "set yrange [*:*]\nset format y '%g'\n";
    ++panel;
  };
  auto event_lines = [&]() {
    s << "unset arrow\n";
    if (events.size() > kMaxEventLines) return;
    for (const Event& e : events) {
      s << "set arrow from " << e.t << ", graph 0 to " << e.t
        << ", graph 1 nohead dashtype 2 lc rgb '#BBBBBB'\n";
    }
  };
  // States.
  open_panel(time_panels == 1);
  event_lines();
  std::set<std::string> units;
  for (std::size_t i = 0; i < shown; ++i) {
    const auto unit = scene.view.units.find(names[i]);
    units.insert(unit == scene.view.units.end() ? "" : unit->second);
  }
  // Headroom above the curves for the key (a row of about a tenth of the panel per state),
  // so that it covers no maximum.
  s << "set offsets 0, 0, graph " << 0.12 * static_cast<double>(shown) << ", 0\n";
  s << "set ylabel "
    << Quote(units.size() == 1 && !units.begin()->empty() ? "state [" + *units.begin() + "]"
                                                          : "state")
    << "\nplot ";
  for (std::size_t i = 0; i < shown; ++i) {
    std::string title = StateAxisLabel(scene.view, names[i]);
    if (i + 1 == shown && shown < names.size()) {
      title += " (first " + std::to_string(shown) + " of " + std::to_string(names.size()) + ")";
    }
    s << (i ? ", " : "") << Quote(directory + "/curves.dat") << " using 1:" << i + 2
      << " with lines lw 2 title " << Quote(title);
  }
  s << "\nset offsets 0, 0, 0, 0\n";
  // Multipliers (piecewise constant on the intervals that end at their times), or counts.
  if (effects_panel) {
    open_panel(panel + 1 == time_panels);
    event_lines();
    if (counts.empty()) {
      // The first kMaxMultiplierLines multipliers, named (more would not be readable).
      const std::size_t drawn = std::min(multiplier_columns.size(), kMaxMultiplierLines);
      // FESD: lines through the stage values, so that a value varying within an element is
      // drawn as it varies. A jump happens only at a switch (switches end elements): at an
      // event time the line jumps to the next element's first stage value and holds it up to
      // that stage.
      std::string source = dense_csv, style = "fsteps";
      const std::size_t stages_per_element = StagesPerElement(report);
      if (&dense == &report.stage_trajectory && stages_per_element > 0) {
        source = directory + "/multipliers.csv";
        style = "lines";
        std::ofstream out(source);
        out << std::setprecision(17);
        const std::size_t offset = 2 + names.size();  // first algebraic CSV column (1-based)
        auto row = [&](double t, std::size_t k) {
          out << t;
          for (std::size_t i = 0; i < drawn; ++i) {
            out << ","
                << dense.algebraic[k][static_cast<Eigen::Index>(
                       static_cast<std::size_t>(multiplier_columns[i].second) - offset)];
          }
          out << "\n";
        };
        std::vector<double> event_times;
        for (const Event& e : events) event_times.push_back(e.t);
        std::sort(event_times.begin(), event_times.end());
        auto at_event = [&](double t) {
          const auto it = std::lower_bound(event_times.begin(), event_times.end(),
                                           t - 1e-12 * std::max(1.0, std::fabs(t)));
          return it != event_times.end() &&
                 std::fabs(*it - t) <= 1e-12 * std::max(1.0, std::fabs(t));
        };
        double start = t0;
        for (std::size_t k = 0; k < dense.size(); ++k) {
          if (k % stages_per_element == 0 && (k == 0 || at_event(start))) row(start, k);
          row(dense.t[k], k);
          if ((k + 1) % stages_per_element == 0) start = dense.t[k];
        }
      }
      s << "set ylabel 'multiplier'\nplot ";
      for (std::size_t i = 0; i < drawn; ++i) {
        std::string title = multiplier_columns[i].first;
        if (i + 1 == drawn && drawn < multiplier_columns.size()) {
          title += " (first " + std::to_string(drawn) + " of " +
                   std::to_string(multiplier_columns.size()) + ")";
        }
        const int column =
            style == "lines" ? static_cast<int>(i) + 2 : multiplier_columns[i].second;
        s << (i ? ", " : "") << Quote(source) << " using 1:" << column << " with " << style
          << " lw 1.6 title " << Quote(title);
      }
      s << "\n";
    } else {
      s << "set datafile separator whitespace\nset ylabel 'active constraints'\nplot ";
      for (std::size_t i = 0; i < counts.size(); ++i) {
        s << (i ? ", " : "") << Quote(directory + "/active_counts.dat") << " using 1:" << i + 2
          << " with steps lw 1.6 title " << Quote(counts[i].first + " (count)");
      }
      s << "\nset datafile separator ','\n";
    }
  }
  // Bands: one row each, coloured by state.
  if (!band_rows.empty()) {
    open_panel(panel + 1 == time_panels);
    event_lines();
    s << "unset ylabel\nset yrange [-0.5:" << band_rows.size() - 0.5 << "] reverse\nset ytics (";
    for (std::size_t r = 0; r < band_rows.size(); ++r) {
      s << (r ? ", " : "") << Quote(band_rows[r].name) << " " << r;
    }
    s << ")\nunset grid\nset grid xtics\n";
    int object = 1;
    for (std::size_t r = 0; r < band_rows.size(); ++r) {
      for (const Band& b : band_rows[r].bands) {
        s << "set object " << object++ << " rect from " << b.start << ", " << r - 0.35 << " to "
          << b.end << ", " << r + 0.35 << " fc rgb '" << kBandColors[b.color % 4]
          << "' fs solid 0.8 noborder\n";
      }
    }
    s << "unset key\nplot -10 notitle\nset yrange [*:*] noreverse\nset grid\nunset object\n";
  }
  // Events: marks in named rows, shaped by kind.
  if (!events.empty()) {
    open_panel(true);
    s << "unset arrow\nunset ylabel\nset datafile separator whitespace\nset yrange [-0.5:"
      << event_rows.size() - 0.5 << "] reverse\nset ytics (";
    for (std::size_t r = 0; r < event_rows.size(); ++r) {
      s << (r ? ", " : "") << Quote(event_rows[r]) << " " << r;
    }
    s << ")\nplot ";
    struct KindStyle {
      EventKind kind;
      int point;
      const char* color;
    };
    const KindStyle styles[] = {
        {EventKind::kEnter, 9, "#E45756"},      {EventKind::kLeave, 11, "#4C78A8"},
        {EventKind::kModeSwitch, 7, "#54A24B"}, {EventKind::kSlideStart, 5, "#F58518"},
        {EventKind::kSlideEnd, 4, "#F58518"},   {EventKind::kRelaySwitch, 13, "#B279A2"},
        {EventKind::kAmbiguous, 3, "#000000"}};
    bool first = true;
    for (const KindStyle& style : styles) {
      const bool present = std::any_of(events.begin(), events.end(),
                                       [&](const Event& e) { return e.kind == style.kind; });
      if (!present) continue;
      s << (first ? "" : ", ") << Quote(directory + "/events.dat")
        << " using 1:($3 == " << static_cast<int>(style.kind) << " ? $2 : 1/0) with points pt "
        << style.point << " ps 1.3 lc rgb '" << style.color << "' title "
        << Quote(ToString(style.kind));
      first = false;
    }
    s << "\nset yrange [*:*] noreverse\nset datafile separator ','\n";
  }
  // Phase portrait.
  nlohmann::json geometry;
  if (phase) {
    const double phase_bottom = 60.0 / height, phase_top = 1.0 - 40.0 / height;
    s << "unset arrow\nunset object\nunset label\nset lmargin at screen " << kPhaseLeft
      << "\nset rmargin at screen " << kPhaseRight << "\nset tmargin at screen " << phase_top
      << "\nset bmargin at screen " << phase_bottom << "\nset xrange [" << range[0] << ":"
      << range[1] << "]\nset yrange [" << range[2] << ":" << range[3]
      << "]\nset format x '%g'\nset format y '%g'\nset ytics auto\nset xlabel "
      << Quote(StateAxisLabel(scene.view, names[0])) << "\nset ylabel "
      << Quote(StateAxisLabel(scene.view, names[1]))
      << "\nset key inside top left opaque box lc rgb '#DDDDDD' samplen 2\n"
      << "set title 'phase portrait'\n"
      << "set datafile separator whitespace\nplot " << Quote(directory + "/boundaries.dat")
      << " using 1:2 with lines lw 2 lc rgb '#D62728' title "
      << Quote(scene.Has<SwitchingSurfaces>() && !scene.Has<MovingSet>()
                   ? "switching surfaces"
                   : "set boundary C(t) at events")
      << ", " << Quote(directory + "/phase_path.dat")
      << " using 1:2 with lines lw 1.8 lc rgb '#4C78A8' title 'x(t)'"
      << " , " << Quote(directory + "/phase_start.dat")
      << " using 1:2 with points pt 7 ps 1.2 lc rgb '#000000' title 'x(t0)'\n";
    std::ofstream(directory + "/phase_start.dat")
        << std::setprecision(17) << trajectory.x[0][0] << " " << trajectory.x[0][1] << "\n";
    std::ofstream path(directory + "/phase_path.dat");
    path << std::setprecision(17);
    for (const Vector& x : curve.x) path << x[0] << " " << x[1] << "\n";
    geometry["phase"] = {
        {"left", kPhaseLeft * kFigureWidth}, {"right", kPhaseRight * kFigureWidth},
        {"top", (1.0 - phase_top) * height}, {"bottom", (1.0 - phase_bottom) * height},
        {"xrange", {range[0], range[1]}},    {"yrange", {range[2], range[3]}},
        {"boundary_color", "#D62728"}};
  }
  s << "unset multiplot\n";
  s.close();
  geometry["width"] = kFigureWidth;
  geometry["height"] = height;
  std::ofstream(directory + "/figure.json") << std::setw(2) << geometry << "\n";
  return RunGnuplot(script_path, image) ? image : "";
}

}  // namespace moreau::tool
