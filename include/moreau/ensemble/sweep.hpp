#pragma once
/// @file
/// Ensembles: parameter sweeps and Monte Carlo over a scene's named values (the `--set`
/// names: parameters, "x0.<state>", "tf"), each run through moreau::Simulate, on a thread pool.
///
/// A sweep is a list of runs. Grids form a product (the first grid varies slowest); samples
/// draw `num_samples` values per grid point (a sweep with samples only has `num_samples`
/// runs). Run i is fully determined by (spec, i): grid values come from i's position in the
/// product, and sample values from a counter-based generator keyed by (seed, i, sample name)
/// (SplitMix64 and Box-Muller, written out here so that every machine and thread count
/// draws the same numbers), so any subset of runs (RunSweep's `indices`) computes rows that
/// are bit-identical to the same rows of a full sweep, whatever the number of threads,
/// processes or machines and the order in which runs finish.
///
/// Every run yields a row: a numerical failure is the integrator's status and message, and a
/// drawn value that makes the scene invalid (a negative horizon, x0 outside a moving set) is
/// the status "invalid_input" with the library's message; any other exception in a run (out of
/// memory, ...) is the status "error" with its message. No row is ever lost.

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// A grid over one named value: `count` points from `start` to `stop` (inclusive, linear), or
/// explicit `values` when given.
struct SweepGrid {
  /// The named value (a `--set` name: a parameter, x0.NAME for the state NAME, or tf).
  std::string name;
  /// Its values, in order.
  std::vector<double> values;
};
/// Parses "name=start:stop:count" (count >= 1; count 1 means start only). Throws
/// std::invalid_argument naming the problem.
SweepGrid ParseSweepGrid(const std::string& text);

/// A sampled named value: normal (mean a, standard deviation b >= 0) or uniform on [a, b).
struct SweepSample {
  /// The distribution of a sampled value.
  enum class Distribution { kNormal, kUniform };
  /// The named value (a `--set` name).
  std::string name;
  /// Normal (a = mean, b = standard deviation) or uniform on [a, b).
  Distribution distribution = Distribution::kUniform;
  /// Mean (normal) or lower end (uniform).
  double a = 0.0;
  /// Standard deviation (normal) or upper end (uniform).
  double b = 1.0;
};
/// Parses "name=normal:mean:std" or "name=uniform:a:b". Throws std::invalid_argument.
SweepSample ParseSweepSample(const std::string& text);

/// A sweep: grids (a product, the first varying slowest) and samples per grid point. Run i is
/// determined by the spec and i alone (counter-based random numbers), so any subset of runs on any
/// number of threads or machines gives the same rows.
struct SweepSpec {
  /// The grids, in order.
  std::vector<SweepGrid> grids;
  /// The sampled values.
  std::vector<SweepSample> samples;
  long num_samples = 0;  ///< draws per grid point (>= 1 when samples are given)
  /// Seed of the samples (run i draws from a generator keyed by seed, i and the name).
  std::uint64_t seed = 0;
  /// Event times recorded per row (event_1 ... event_K; NaN where a run has fewer events).
  int num_event_times = 5;

  /// Number of runs: the product of the grid sizes times max(1, num_samples).
  long NumRuns() const;
  /// The varied names in column order: grids, then samples.
  std::vector<std::string> VariedNames() const;
  /// The values of the varied names for run `index` (0 <= index < NumRuns()).
  std::vector<double> ValuesOf(long index) const;
  /// Throws std::invalid_argument for an empty spec, a name that is not an overridable name
  /// of `scene`, a name varied twice, samples without num_samples (or the reverse), or a sweep
  /// of more than kMaxSweepRuns runs.
  void Validate(const Scene& scene) const;
};

/// Largest sweep (runs) accepted in one call: a table of this many rows already takes
/// gigabytes; larger studies are split into calls over index ranges.
inline constexpr long kMaxSweepRuns = 100'000'000;

/// One row of the result table.
struct SweepRow {
  /// Run index in [0, NumRuns()).
  long index = 0;
  std::vector<double> values;  ///< varied values (SweepSpec::VariedNames order)
  std::string status;          ///< the integrator's status, or "invalid_input"
  /// True if the integrator reported success.
  bool success = false;
  /// The integrator's message, or the library's for invalid input.
  std::string message;
  /// Time reached.
  double final_time = 0.0;
  Vector final_state;  ///< NaN-filled for invalid_input rows
  /// Number of events of the run.
  long num_events = 0;
  std::vector<double> event_times;  ///< first num_event_times events, NaN-padded
  std::vector<double> stats;        ///< the integrator's declared stats (NaN if invalid)
  double cpu_seconds = 0.0;         ///< thread CPU time of the whole run (setup included)
};

/// The table of a sweep: one row per run, in index order, with the column names.
struct SweepResult {
  /// The scene's name.
  std::string scene;
  std::string integrator;  ///< resolved ("auto" replaced)
  /// Names of the varied values (SweepSpec::VariedNames).
  std::vector<std::string> varied_names;
  /// Names of the final-state columns.
  std::vector<std::string> state_names;
  /// Names of the integrator's declared statistics (SweepRow::stats).
  std::vector<std::string> stat_names;
  /// Event-time columns per row.
  int num_event_times = 0;
  std::vector<SweepRow> rows;  ///< in index order
  /// Wall-clock time of the sweep.
  double wall_seconds = 0.0;
  /// Worker threads used.
  int threads = 1;
};

/// Called from worker threads after each run with (runs done, runs in all); may be empty.
using SweepProgress = std::function<void(long done, long total)>;

/// Runs the sweep (or only the runs in `indices`, in that order, if not empty) with `threads`
/// worker threads (0: all cores). Throws std::invalid_argument for an invalid spec or
/// settings (checked once, before any run).
SweepResult RunSweep(const Scene& scene, const SweepSpec& spec, const SimulationSettings& settings,
                     int threads = 0, const std::vector<long>& indices = {},
                     const SweepProgress& progress = {});

/// The table as CSV (header: index, varied names, status, success, message, final_time,
/// x.NAME per state NAME, num_events, event_1..K, stats..., cpu_seconds; 17 significant
/// digits).
void WriteSweepCsv(const SweepResult& result, const std::string& path);

}  // namespace moreau
