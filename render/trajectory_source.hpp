#pragma once
// Trajectories read once, front to back, and sampled at increasing times: what lets an
// animation of 10^4 bodies stream (two recorded points in memory, whatever the length).

#include <fstream>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/integrators/simulation.hpp"

namespace moreau::render {

// Recorded points (t_k, x_k) with t_k non-decreasing, one at a time.
class TrajectorySource {
 public:
  virtual ~TrajectorySource() = default;
  // The next point; false at the end.
  virtual bool Next(double* t, Vector* x) = 0;
};

// A trajectory in memory (a SimulationResult's).
class MemorySource : public TrajectorySource {
 public:
  explicit MemorySource(const Trajectory& trajectory) : trajectory_(trajectory) {}
  bool Next(double* t, Vector* x) override;

 private:
  const Trajectory& trajectory_;
  std::size_t next_ = 0;
};

// trajectory.csv or stages.csv of a run directory (header "t,<states>,..."): the first
// 1 + num_states columns of each row, parsed as read. Throws std::invalid_argument for a file
// that cannot be read, a header that does not start with t and the states, or a bad number
// (with the line).
class CsvSource : public TrajectorySource {
 public:
  CsvSource(const std::string& path, const std::vector<std::string>& state_names);
  bool Next(double* t, Vector* x) override;

 private:
  std::string path_;
  std::ifstream in_;
  std::string line_;
  long line_number_ = 1;
  int num_states_ = 0;
};

// x(t) at increasing times t by linear interpolation between consecutive recorded points (at a
// time recorded twice, e.g. at an event, the later point). Holds two points.
class Sampler {
 public:
  explicit Sampler(TrajectorySource* source);
  // x(t) for t >= the previous call's t; false if the source is empty. Times before the first
  // point give the first point, after the last point the last one.
  bool At(double t, Vector* x);

 private:
  TrajectorySource* source_;
  bool started_ = false, done_ = false;
  double t_a_ = 0.0, t_b_ = 0.0;
  Vector x_a_, x_b_;
};

}  // namespace moreau::render
