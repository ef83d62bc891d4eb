#include "random_scenes.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <sstream>

#include "moreau/model/scene_file.hpp"

namespace moreau::testing {
namespace {

// splitmix64 (Steele, Lea and Flood, Fast splittable pseudorandom number generators, 2014):
// the same numbers on every platform, unlike the standard distributions.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed) {}
  std::uint64_t Next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  double In(double a, double b) { return a + (b - a) * Uniform(); }
  double Log10In(double a, double b) { return std::pow(10.0, In(a, b)); }
  int Below(int n) { return static_cast<int>(Next() % static_cast<std::uint64_t>(n)); }
  double Sign() { return Below(2) == 0 ? -1.0 : 1.0; }

 private:
  std::uint64_t state_;
};

std::string Number(double value) {
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.17g", value);
  return buffer;
}

// Rate terms in the dimensionless time s: "(a) + (b)".
std::string Sum(const std::vector<std::string>& terms) {
  if (terms.empty()) return "0";
  std::string sum;
  for (const std::string& term : terms) sum += (sum.empty() ? "" : " + ") + ("(" + term + ")");
  return sum;
}

std::string Quoted(const std::string& text) { return "\"" + text + "\""; }

std::string List(const std::vector<std::string>& items) {
  std::string out = "[";
  for (std::size_t i = 0; i < items.size(); ++i) out += (i > 0 ? ", " : "") + items[i];
  return out + "]";
}

// A field on n states: `rate` (an expression in s-units, times 1/tau) on state i, 0 elsewhere.
std::string Field(int n, int i, const std::string& rate) {
  std::vector<std::string> entries;
  for (int k = 0; k < n; ++k) entries.push_back(Quoted(k == i ? "(" + rate + ")/tau" : "0"));
  return List(entries);
}

enum class Family { kPulse, kSliding, kFloor, kBrush, kDiode, kStop, kRelay };
constexpr int kFamilies = 7;
const char* Name(Family family) {
  switch (family) {
    case Family::kPulse:
      return "pulse";
    case Family::kSliding:
      return "sliding";
    case Family::kFloor:
      return "floor";
    case Family::kBrush:
      return "brush";
    case Family::kDiode:
      return "diode";
    case Family::kStop:
      return "stop";
    case Family::kRelay:
      return "relay";
  }
  return "?";
}

}  // namespace

RandomScene GenerateRandomScene(std::uint64_t seed) {
  Random random(seed * 0x2545f4914f6cdd1dULL + 1);
  RandomScene out;
  out.seed = seed;
  const double tau = random.Log10In(-6.0, 3.0);
  const double horizon = random.In(2.0, 8.0);  // in s
  out.time_scale = tau;
  // One or two effects of different families.
  std::vector<Family> families{static_cast<Family>(random.Below(kFamilies))};
  if (random.Below(2) == 1) {
    Family second = static_cast<Family>(random.Below(kFamilies));
    while (second == families[0]) second = static_cast<Family>(random.Below(kFamilies));
    families.push_back(second);
  }
  int needed = 0;
  for (Family f : families) needed += f == Family::kBrush ? 2 : 1;
  const int n = needed + random.Below(2);  // and perhaps a free state
  // Owners: which effect a state belongs to (-1: free).
  std::vector<int> owner(static_cast<std::size_t>(n), -1);
  std::vector<std::vector<int>> states(families.size());
  int next = 0;
  for (std::size_t f = 0; f < families.size(); ++f) {
    const int count = families[f] == Family::kBrush ? 2 : 1;
    for (int c = 0; c < count; ++c) {
      owner[static_cast<std::size_t>(next)] = static_cast<int>(f);
      states[f].push_back(next++);
    }
  }
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) names.push_back("x" + std::to_string(i + 1));
  std::vector<std::vector<std::string>> rate(static_cast<std::size_t>(n));
  std::vector<double> x0(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) x0[static_cast<std::size_t>(i)] = random.In(-0.5, 0.5);
  // Free states: damped, coupled to the next state, forced, with a mild quadratic term.
  for (int i = 0; i < n; ++i) {
    if (owner[static_cast<std::size_t>(i)] >= 0) continue;
    const std::string& x = names[static_cast<std::size_t>(i)];
    const std::string& y = names[static_cast<std::size_t>((i + 1) % n)];
    auto& r = rate[static_cast<std::size_t>(i)];
    r.push_back(Number(-random.In(0.2, 2.0)) + "*" + x);
    if (n > 1) r.push_back(Number(random.In(-0.5, 0.5)) + "*" + y);
    r.push_back(Number(random.In(0.0, 1.0)) + "*sin(" + Number(random.In(0.5, 5.0)) + "*s + " +
                Number(random.In(0.0, 6.0)) + ")");
    r.push_back(Number(random.In(-0.2, 0.2)) + "*" + x + "*" + y);
  }
  std::ostringstream parameters, effects;
  parameters << "[[parameters]]\nname = \"tau\"\nvalue = " << Number(tau) << "\n";
  std::vector<double> stops_s;
  std::string family_names;
  for (std::size_t f = 0; f < families.size(); ++f) {
    const Family family = families[f];
    family_names += (f > 0 ? "+" : "") + std::string(Name(family));
    const int i = states[f][0];
    const std::string& x = names[static_cast<std::size_t>(i)];
    auto& r = rate[static_cast<std::size_t>(i)];
    double& xi0 = x0[static_cast<std::size_t>(i)];
    const std::string name = std::string(Name(family)) + std::to_string(f + 1);
    effects << "\n[[effects]]\nname = \"" << name << "\"\n";
    switch (family) {
      case Family::kPulse: {
        // x_i' gains k while the pulse is above 1/2: for |s - s0| < w sqrt(ln 2).
        r.push_back(Number(-random.In(0.2, 1.0)) + "*" + x);
        const double s0 = random.In(0.2, 0.8) * horizon, w = random.Log10In(-3.0, -1.0);
        const double k = random.Sign() * random.In(0.5, 2.0);
        effects << "kind = \"switching\"\nsurfaces = [\"exp(-((s - " << Number(s0) << ")/"
                << Number(w) << ")^2) - 0.5\"]\nbelow = [" << Field(n, i, "0") << "]\nabove = ["
                << Field(n, i, Number(k)) << "]\n";
        stops_s.push_back(s0);
        break;
      }
      case Family::kSliding: {
        // Fields D on either side push x_i towards b; a forcing a sin may exceed D (crossing).
        const double b = random.In(-0.3, 0.3), d = random.In(0.5, 1.5);
        r.push_back(Number(random.In(0.0, 2.0)) + "*sin(" + Number(random.In(0.5, 3.0)) + "*s)");
        effects << "kind = \"switching\"\nsurfaces = [\"" << x << " - " << Number(b)
                << "\"]\nbelow = [" << Field(n, i, Number(d)) << "]\nabove = ["
                << Field(n, i, Number(-d)) << "]\n";
        break;
      }
      case Family::kFloor: {
        // x_i drifts down onto the floor h sin(om s) + b.
        const double h = random.In(0.05, 0.3), om = random.In(0.5, 3.0), b = random.In(-0.5, 0.0);
        r.push_back(Number(-random.In(0.5, 1.5)));
        r.push_back(Number(random.In(0.0, 0.3)) + "*sin(" + Number(random.In(0.5, 3.0)) + "*s)");
        xi0 = b + h + random.In(0.05, 0.5);
        effects << "kind = \"moving_set\"\nconstraints = [\"" << x << " - (" << Number(h) << "*sin("
                << Number(om) << "*s) + " << Number(b) << ")\"]\n";
        break;
      }
      case Family::kBrush: {
        // A point at rest (no dynamics of its own) and a disc of radius R whose centre moves at
        // unit speed along the line dy below it, passing at s_c: it grazes the point.
        const int j = states[f][1];
        const std::string& y = names[static_cast<std::size_t>(j)];
        const double radius = random.Log10In(-3.0, -1.0);
        const double dy = radius * random.In(0.1, 0.9);
        const double sc = random.In(0.3, 0.7) * horizon;
        effects << "kind = \"moving_set\"\nconstraints = [\"(" << x << " - ("
                << Number(x0[static_cast<std::size_t>(i)]) << " + s - " << Number(sc) << "))^2 + ("
                << y << " - " << Number(x0[static_cast<std::size_t>(j)] - dy) << ")^2 - "
                << Number(radius * radius) << "\"]\n";
        stops_s.push_back(sc);
        break;
      }
      case Family::kDiode: {
        // Rectifier: 0 <= lambda _|_ x_i - E sin(om s) + r lambda >= 0, x_i' = -d x_i + lambda.
        r.push_back(Number(-random.In(0.2, 2.0)) + "*" + x);
        const double e = random.In(0.5, 1.5), om = random.In(0.5, 5.0), res = random.In(0.1, 1.0);
        std::vector<std::string> rows;
        for (int k = 0; k < n; ++k) rows.push_back(List({Quoted(k == i ? "1/tau" : "0")}));
        effects << "kind = \"complementarity\"\noutput = [\"" << x << " - " << Number(e) << "*sin("
                << Number(om) << "*s)\"]\ninput_matrix = " << List(rows) << "\nfeedthrough = [[\""
                << Number(res) << "\"]]\n";
        break;
      }
      case Family::kStop: {
        // x_i >= b, pushed up by lambda (index 2): a floor that does not move.
        const double b = random.In(-0.5, 0.0);
        r.push_back(Number(-random.In(0.5, 1.5)));
        r.push_back(Number(random.In(0.0, 1.5)) + "*sin(" + Number(random.In(0.5, 3.0)) + "*s)");
        xi0 = b + random.In(0.05, 0.5);
        std::vector<std::string> rows;
        for (int k = 0; k < n; ++k) rows.push_back(List({Quoted(k == i ? "1/tau" : "0")}));
        effects << "kind = \"complementarity\"\noutput = [\"" << x << " - " << Number(b)
                << "\"]\ninput_matrix = " << List(rows) << "\n";
        break;
      }
      case Family::kRelay: {
        // A thermostat: mode A drives x_i up to theta, mode B down to -theta.
        const double theta = random.In(0.2, 0.5), k = random.In(1.0, 2.0);
        r.push_back(Number(random.In(0.0, 0.5)) + "*sin(" + Number(random.In(0.5, 3.0)) + "*s)");
        xi0 = random.In(-0.9, 0.9) * theta;
        parameters << "\n[[parameters]]\nname = \"lo" << f + 1 << "\"\nvalue = " << Number(-theta)
                   << "\n\n[[parameters]]\nname = \"hi" << f + 1 << "\"\nvalue = " << Number(theta)
                   << "\n";
        effects << "kind = \"hysteresis\"\ninput = \"" << x << "\"\nlower_threshold = \"lo" << f + 1
                << "\"\nupper_threshold = \"hi" << f + 1
                << "\"\nmode_a = " << Field(n, i, Number(k))
                << "\nmode_b = " << Field(n, i, Number(-k)) << "\n";
        break;
      }
    }
  }
  std::vector<std::string> dynamics, initial, quoted_names;
  for (int i = 0; i < n; ++i) {
    dynamics.push_back(Quoted("(" + Sum(rate[static_cast<std::size_t>(i)]) + ")/tau"));
    initial.push_back(Number(x0[static_cast<std::size_t>(i)]));
    quoted_names.push_back(Quoted(names[static_cast<std::size_t>(i)]));
  }
  std::ostringstream toml;
  toml << "name = \"random_" << seed << "\"\n"
       << "description = \"random scene " << seed << ": " << family_names
       << ", tau = " << Number(tau) << "\"\n"
       << "states = " << List(quoted_names) << "\n"
       << "x0 = " << List(initial) << "\n"
       << "tf = " << Number(tau * horizon) << "\n"
       << "dynamics = " << List(dynamics) << "\n\n"
       << parameters.str() << "\n[defs]\ns = \"t/tau\"\n"
       << effects.str();
  out.toml = toml.str();
  out.families = family_names;
  out.scene = ParseScene(out.toml, "random_" + std::to_string(seed) + ".toml");
  for (double s : stops_s) out.stop_times.push_back(tau * s);
  out.reference_max_step = tau * horizon / 200.0;
  return out;
}

SimulationSettings DefaultSettings() {
  // Until error control is the default of `auto`: adaptive FESD with Simulate's default
  // tolerances. When it is, this becomes `return {};`.
  return {"fesd", {{"adaptive", true}}};
}

SimulationSettings ReferenceSettings(const RandomScene& scene, bool fine_fesd) {
  if (fine_fesd) {
    const double span = scene.scene.final_time - scene.scene.initial_time;
    return {"fesd", {{"h", span / 2000.0}, {"stages", 3L}, {"tstops", scene.stop_times}}};
  }
  return {"ida",
          {{"rtol", 1e-10},
           {"atol", 1e-12},
           {"max_step", scene.reference_max_step},
           {"tstops", scene.stop_times},
           {"record_steps", false}}};
}

std::string ToString(Verdict verdict) {
  switch (verdict) {
    case Verdict::kAgree:
      return "agree";
    case Verdict::kHonestFailure:
      return "honest failure";
    case Verdict::kSilentDisagreement:
      return "silent disagreement";
    case Verdict::kNoReference:
      return "no reference";
  }
  return "?";
}

Comparison CompareWithReference(const RandomScene& scene) {
  Comparison comparison;
  std::ostringstream detail;
  detail.precision(10);
  SimulationResult run;
  try {
    run = Simulate(scene.scene, DefaultSettings());
  } catch (const std::exception& error) {
    comparison.verdict = Verdict::kHonestFailure;
    comparison.detail = std::string("defaults refused the scene: ") + error.what();
    return comparison;
  }
  SimulationResult reference;
  bool have_reference = false;
  for (bool fine : {false, true}) {
    try {
      reference = Simulate(scene.scene, ReferenceSettings(scene, fine));
      have_reference = reference.success;
    } catch (const std::exception& error) {
      detail << "reference " << (fine ? "fesd" : "ida") << " refused: " << error.what() << "; ";
    }
    if (have_reference) break;
    detail << "reference " << (fine ? "fesd" : "ida") << ": " << reference.status << " "
           << reference.message << "; ";
  }
  detail << "defaults: " << run.status;
  if (!run.success) detail << " (" << run.message << ")";
  for (const std::string& warning : run.warnings) detail << "; warning: " << warning;
  if (!have_reference) {
    comparison.verdict = Verdict::kNoReference;
    comparison.detail = detail.str();
    return comparison;
  }
  if (run.success && run.final_state.size() == reference.final_state.size()) {
    for (Eigen::Index i = 0; i < run.final_state.size(); ++i) {
      comparison.error =
          std::max(comparison.error, std::fabs(run.final_state[i] - reference.final_state[i]) /
                                         (1.0 + std::fabs(reference.final_state[i])));
    }
    if (!(comparison.error == comparison.error)) comparison.error = HUGE_VAL;  // NaN
  }
  detail << "; error " << comparison.error << "; x(T) = [";
  for (Eigen::Index i = 0; i < run.final_state.size(); ++i) {
    detail << (i > 0 ? ", " : "") << run.final_state[i];
  }
  detail << "], reference [";
  for (Eigen::Index i = 0; i < reference.final_state.size(); ++i) {
    detail << (i > 0 ? ", " : "") << reference.final_state[i];
  }
  detail << "] (" << reference.integrator << ")";
  comparison.detail = detail.str();
  if (!run.success) {
    comparison.verdict = Verdict::kHonestFailure;
  } else if (comparison.error <= kAgreement) {
    comparison.verdict = Verdict::kAgree;
  } else {
    // Off the reference: honest only if the run said it might be.
    comparison.verdict =
        run.warnings.empty() ? Verdict::kSilentDisagreement : Verdict::kHonestFailure;
  }
  return comparison;
}

}  // namespace moreau::testing
