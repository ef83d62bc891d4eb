// Parameter sweeps and Monte Carlo on a thread pool (include/moreau/ensemble/sweep.hpp).
#include "moreau/ensemble/sweep.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <thread>

#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"

namespace moreau {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double ParseNumber(const std::string& text, const std::string& what) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  RequireArgument(!text.empty() && end == text.c_str() + text.size() && std::isfinite(value),
                  "bad ", what, " '", text, "': expected a finite number");
  return value;
}

std::vector<std::string> Split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.push_back("");
  return parts;
}

// "name=rest": the name and the rest; throws naming the option.
std::pair<std::string, std::string> SplitAssignment(const std::string& text,
                                                    const std::string& option,
                                                    const std::string& form) {
  const auto equals = text.find('=');
  RequireArgument(equals != std::string::npos && equals > 0, "bad ", option, " '", text,
                  "': expected ", form);
  return {text.substr(0, equals), text.substr(equals + 1)};
}

// SplitMix64 (Steele, Lea, Flood 2014): a counter-based generator, the same on every machine.
std::uint64_t SplitMix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

std::uint64_t HashName(const std::string& name) {
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a
  for (unsigned char c : name) h = (h ^ c) * 1099511628211ull;
  return h;
}

// A uniform double in (0, 1) from 53 random bits (never 0, so log() below is finite).
double Uniform01(std::uint64_t bits) { return (static_cast<double>(bits >> 11) + 0.5) * 0x1.0p-53; }

double Draw(const SweepSample& sample, std::uint64_t seed, long index) {
  const std::uint64_t key =
      SplitMix64(seed ^ SplitMix64(static_cast<std::uint64_t>(index) ^ HashName(sample.name)));
  const double u1 = Uniform01(SplitMix64(key));
  if (sample.distribution == SweepSample::Distribution::kUniform) {
    return sample.a + (sample.b - sample.a) * u1;
  }
  // Box-Muller (one of the pair).
  const double u2 = Uniform01(SplitMix64(key + 1));
  const double z = std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  return sample.a + sample.b * z;
}

}  // namespace

namespace {
// A run that produced no simulation result: status and message, NaN elsewhere.
void FailedRow(const char* status, const char* message, const Scene& scene,
               const SweepResult& result, SweepRow* row) {
  row->status = status;
  row->success = false;
  row->message = message;
  row->final_time = kNaN;
  row->final_state = Vector::Constant(scene.num_states(), kNaN);
  row->stats.assign(result.stat_names.size(), kNaN);
  row->num_events = 0;
}
}  // namespace

SweepGrid ParseSweepGrid(const std::string& text) {
  const auto [name, rest] = SplitAssignment(text, "--grid", "name=start:stop:count");
  const std::vector<std::string> parts = Split(rest, ':');
  RequireArgument(parts.size() == 3, "bad --grid '", text, "': expected name=start:stop:count");
  const double start = ParseNumber(parts[0], "grid start");
  const double stop = ParseNumber(parts[1], "grid stop");
  const double count = ParseNumber(parts[2], "grid count");
  RequireArgument(count >= 1 && count == std::floor(count) && count <= kMaxSweepRuns,
                  "bad --grid '", text, "': count must be a whole number >= 1, got ", parts[2]);
  SweepGrid grid;
  grid.name = name;
  const long n = static_cast<long>(count);
  for (long k = 0; k < n; ++k) {
    // Linear points, the last exactly `stop`.
    grid.values.push_back(n == 1 ? start
                                 : (k == n - 1 ? stop
                                               : start + (stop - start) * static_cast<double>(k) /
                                                             static_cast<double>(n - 1)));
  }
  return grid;
}

SweepSample ParseSweepSample(const std::string& text) {
  const auto [name, rest] =
      SplitAssignment(text, "--sample", "name=normal:mean:std or name=uniform:a:b");
  const std::vector<std::string> parts = Split(rest, ':');
  RequireArgument(parts.size() == 3 && (parts[0] == "normal" || parts[0] == "uniform"),
                  "bad --sample '", text, "': expected name=normal:mean:std or name=uniform:a:b");
  SweepSample sample;
  sample.name = name;
  sample.a = ParseNumber(parts[1], parts[0] == "normal" ? "mean" : "lower bound");
  sample.b = ParseNumber(parts[2], parts[0] == "normal" ? "standard deviation" : "upper bound");
  if (parts[0] == "normal") {
    sample.distribution = SweepSample::Distribution::kNormal;
    RequireArgument(sample.b >= 0.0, "bad --sample '", text,
                    "': the standard deviation must be >= 0, got ", sample.b);
  } else {
    RequireArgument(sample.a < sample.b, "bad --sample '", text,
                    "': uniform:a:b needs a < b, got a = ", sample.a, ", b = ", sample.b);
  }
  return sample;
}

long SweepSpec::NumRuns() const {
  long runs = 1;
  for (const SweepGrid& grid : grids) {
    const long size = static_cast<long>(grid.values.size());
    runs = size == 0 ? 0 : (runs > kMaxSweepRuns / size ? kMaxSweepRuns + 1 : runs * size);
  }
  const long draws = samples.empty() ? 1 : num_samples;
  if (draws <= 0) return 0;
  return runs > kMaxSweepRuns / draws ? kMaxSweepRuns + 1 : runs * draws;
}

std::vector<std::string> SweepSpec::VariedNames() const {
  std::vector<std::string> names;
  for (const SweepGrid& grid : grids) names.push_back(grid.name);
  for (const SweepSample& sample : samples) names.push_back(sample.name);
  return names;
}

std::vector<double> SweepSpec::ValuesOf(long index) const {
  std::vector<double> values(grids.size() + samples.size());
  const long draws = samples.empty() ? 1 : num_samples;
  long point = index / draws;  // grid point; the first grid varies slowest
  for (std::size_t g = grids.size(); g-- > 0;) {
    const long size = static_cast<long>(grids[g].values.size());
    values[g] = grids[g].values[static_cast<std::size_t>(point % size)];
    point /= size;
  }
  for (std::size_t s = 0; s < samples.size(); ++s) {
    values[grids.size() + s] = Draw(samples[s], seed, index);
  }
  return values;
}

void SweepSpec::Validate(const Scene& scene) const {
  RequireArgument(!grids.empty() || !samples.empty(),
                  "a sweep needs at least one --grid or --sample");
  RequireArgument(samples.empty() || num_samples >= 1,
                  "--sample needs --samples N with N >= 1, got ", num_samples);
  RequireArgument(!samples.empty() || num_samples == 0,
                  "--samples applies only with --sample name=distribution");
  const std::vector<std::string> valid = OverridableNames(scene);
  std::set<std::string> seen;
  for (const std::string& name : VariedNames()) {
    if (std::find(valid.begin(), valid.end(), name) == valid.end()) {
      std::string list;
      for (const std::string& v : valid) list += (list.empty() ? "" : ", ") + v;
      ThrowInvalidArgument("scene '", scene.name, "' has no value named '", name,
                           "' to vary; valid names: ", list);
    }
    RequireArgument(seen.insert(name).second, "'", name, "' is varied twice");
  }
  for (const SweepGrid& grid : grids) {
    RequireArgument(!grid.values.empty(), "grid '", grid.name, "' has no values");
    for (double v : grid.values) {
      RequireArgument(std::isfinite(v), "grid '", grid.name, "' has a non-finite value");
    }
  }
  RequireArgument(num_event_times >= 0, "event times per row must be >= 0, got ", num_event_times);
  RequireArgument(NumRuns() <= kMaxSweepRuns, "a sweep of more than ", kMaxSweepRuns,
                  " runs; split it into index ranges");
}

SweepResult RunSweep(const Scene& scene, const SweepSpec& spec, const SimulationSettings& settings,
                     int threads, const std::vector<long>& indices, const SweepProgress& progress) {
  spec.Validate(scene);
  ValidateScene(scene);
  SimulationSettings resolved = settings;
  if (resolved.integrator == "auto") resolved.integrator = AutomaticIntegrator(scene);
  ValidateSimulationSettings(scene, resolved);  // once, before any run
  const long total_runs = spec.NumRuns();
  std::vector<long> runs = indices;
  if (runs.empty()) {
    runs.resize(static_cast<std::size_t>(total_runs));
    for (long i = 0; i < total_runs; ++i) runs[static_cast<std::size_t>(i)] = i;
  }
  for (long i : runs) {
    RequireArgument(i >= 0 && i < total_runs, "run index ", i, " is outside the sweep's ",
                    total_runs, " runs");
  }

  SweepResult result;
  result.scene = scene.name;
  result.integrator = resolved.integrator;
  result.varied_names = spec.VariedNames();
  result.state_names = scene.state_names;
  for (const StatSpec& stat : FindIntegrator(resolved.integrator).stats) {
    result.stat_names.push_back(stat.name);
  }
  result.num_event_times = spec.num_event_times;
  result.rows.resize(runs.size());
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  threads = static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(threads),
                                                   std::max<std::size_t>(1, runs.size())));
  result.threads = threads;

  const auto start = std::chrono::steady_clock::now();
  std::atomic<long> next{0}, done{0};
  const long count = static_cast<long>(runs.size());
  auto work = [&]() {
    for (long k = next++; k < count; k = next++) {
      const long index = runs[static_cast<std::size_t>(k)];
      SweepRow& row = result.rows[static_cast<std::size_t>(k)];
      const double cpu_start = ThreadCpuSeconds();
      row.index = index;
      row.values = spec.ValuesOf(index);
      row.event_times.assign(static_cast<std::size_t>(spec.num_event_times), kNaN);
      try {
        Scene copy = scene;  // deep copy: model functions keep per-object workspaces
        for (std::size_t v = 0; v < row.values.size(); ++v) {
          SetSceneValue(&copy, result.varied_names[v], row.values[v]);
        }
        const SimulationResult run = Simulate(copy, resolved);
        row.status = run.status;
        row.success = run.success;
        row.message = run.message;
        row.final_time = run.final_time;
        row.final_state = run.final_state;
        row.num_events = static_cast<long>(run.events.size());
        for (std::size_t e = 0; e < run.events.size() && e < row.event_times.size(); ++e) {
          row.event_times[e] = run.events[e].t;
        }
        for (const auto& [name, value] : run.stats) row.stats.push_back(value);
      } catch (const std::invalid_argument& error) {
        // A drawn value the scene does not accept: a row, never a lost run.
        FailedRow("invalid_input", error.what(), scene, result, &row);
      } catch (const std::exception& error) {
        // Anything else (out of memory, ...) must not escape a worker thread (std::terminate):
        // it is a row too.
        FailedRow("error", error.what(), scene, result, &row);
      }
      row.cpu_seconds = ThreadCpuSeconds() - cpu_start;
      const long finished = ++done;
      if (progress) progress(finished, count);
    }
  };
  if (threads == 1) {
    work();
  } else {
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t) pool.emplace_back(work);
    for (std::thread& thread : pool) thread.join();
  }
  result.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

namespace {
std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}
}  // namespace

void WriteSweepCsv(const SweepResult& result, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << "index";
  for (const std::string& name : result.varied_names) out << "," << CsvField(name);
  out << ",status,success,message,final_time";
  for (const std::string& name : result.state_names) out << ",x." << CsvField(name);
  out << ",num_events";
  for (int e = 1; e <= result.num_event_times; ++e) out << ",event_" << e;
  for (const std::string& name : result.stat_names) out << "," << CsvField(name);
  out << ",run_cpu_seconds\n" << std::setprecision(17);
  for (const SweepRow& row : result.rows) {
    out << row.index;
    for (double v : row.values) out << "," << v;
    out << "," << row.status << "," << (row.success ? 1 : 0) << "," << CsvField(row.message) << ","
        << row.final_time;
    for (Eigen::Index i = 0; i < row.final_state.size(); ++i) out << "," << row.final_state[i];
    out << "," << row.num_events;
    for (double t : row.event_times) out << "," << t;
    for (double s : row.stats) out << "," << s;
    out << "," << row.cpu_seconds << "\n";
  }
}

}  // namespace moreau
