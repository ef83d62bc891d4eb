#pragma once
// Directional and adjoint sensitivities of a FESD run (docs/sensitivities.md). Private to
// moreau::integrators.
//
// The derivative of the run is a chain of linear maps on the augmented sensitivity state
//   s = (dy (n_y), dtau (1), dstep_end (1)),
// dtau the derivative of (tau - step end) and dstep_end that of the current step's end
// (adaptive steps and replays), driven by the parameter directions (dp, du_1, ..., du_S):
//   GroupStep       the implicit function theorem on one converged group system
//   SaltationStep   a switch found exactly on a step boundary (rank-one update)
//   ClockStep       time-freezing: a step's length from the clock, dtau = factor dclock
//   StepStart       adaptive steps: the step end moves with its start unless it lands
//   ProjectionStep  an initial state outside the moving sets projected onto them
//   SampleStep      the state at a sample time (seeds of the adjoint functional)
// FesdSensitivities::lowered applies them to the identity (full matrices, fesd_sensitivities.cpp
// LocalTransfer); directional sensitivities apply them to a block of k directions as the run
// goes; the adjoint records them (the tape) and applies their transposes in reverse order.

#include <cstddef>
#include <memory>
#include <variant>
#include <vector>

#include "../common/spill_file.hpp"
#include "group_system.hpp"

namespace moreau::internal {

// A converged group: enough to evaluate its system again at the solution (checkpoint) and
// refactorize its Jacobian in the reverse sweep.
struct GroupStep {
  GroupSetup setup;
  Vector w;           // the converged unknowns (empty when in the checkpoint file)
  int segment = 0;    // control segment (inputs u_segment)
  int remaining = 1;  // element count that fixed the lengths (h = rest / remaining)
  int layout = 0;     // index of the working set (near-active filter) in SensitivityTape
  // In the checkpoint file (beyond the memory limit): w and setup.y_start at this offset.
  long file_offset = -1;
  Eigen::Index w_size = 0, y_size = 0;
};

// Checkpoints beyond the memory limit, in a temporary file (common/spill_file.hpp), written
// forward and read back by the sweep.
class CheckpointFile {
 public:
  // Writes w and step->setup.y_start at `offset` (the end of the kept checkpoints), empties
  // them in *step and returns the next offset. Throws std::runtime_error if the file cannot
  // be written.
  long Write(long offset, GroupStep* step);
  // Reads a written step's w and y_start back into *step.
  void Read(GroupStep* step);

 private:
  SpillFile file_;
};

// s_y -= jump (g_y s_y + g_p dp + g_u du_segment) / rate, jump = F_- - F_+.
struct SaltationStep {
  Vector jump;
  Eigen::RowVectorXd g_y, g_p, g_u;
  double rate = 1.0;
  int segment = 0;
};

// s_tau = factor s_clock (factor 0: a frozen step's length does not move).
struct ClockStep {
  int clock = 0;
  double factor = 0.0;
};

// d_tau = s_tau + s_end; d_end = lands ? (clock_targets ? d_tau - s_clock : 0) : d_tau;
// s_tau = d_tau - d_end; s_end = d_end.
struct StepStart {
  bool lands = false;
  bool clock_targets = false;
  int clock = 0;
};

// s_x = d_x0 s_x + d_t s_clock + d_p dp + d_u du_0.
struct ProjectionStep {
  Matrix d_x0;
  Vector d_t;
  Matrix d_p, d_u;
  int clock = 0;
};

struct SampleStep {
  int sample = 0;
};

using TapeStep =
    std::variant<GroupStep, SaltationStep, ClockStep, StepStart, ProjectionStep, SampleStep>;

// What the run tracks beside (or instead of) the full matrices.
struct SensitivityTape {
  // Directions: d ((n_y + 2) x k) in the augmented state, theta ((n_p + n_u S) x k) of the
  // parameters and inputs (constant through the run).
  bool directional = false;
  Matrix d;
  Matrix theta;
  std::vector<Matrix> sample_d;  // d at every sample (n_y rows)

  // Adjoint: the steps of the run in order, and the working sets they refer to.
  bool adjoint = false;
  std::vector<TapeStep> steps;
  std::vector<std::vector<bool>> layouts;
  std::vector<Vector> segment_inputs;  // u of every control segment
  Vector parameters;
  std::size_t bytes = 0;         // memory the steps hold
  std::size_t memory_limit = 0;  // bytes (0: none); checkpoints beyond go to the file
  long file_bytes = 0;           // the file's used length
  std::unique_ptr<CheckpointFile> file;

  // Sample times (physical) and the lowered states reached there (the first next_sample).
  std::vector<double> sample_times;
  std::vector<Vector> sample_states;
  std::size_t next_sample = 0;

  // What an adaptive attempt rolls back.
  struct Mark {
    Matrix d;
    std::size_t steps = 0, bytes = 0, next_sample = 0;
    long file_bytes = 0;
  };
  Mark Save() const { return {d, steps.size(), bytes, next_sample, file_bytes}; }
  void Restore(const Mark& mark) {
    d = mark.d;
    steps.resize(mark.steps, TapeStep(SampleStep{}));
    bytes = mark.bytes;
    file_bytes = mark.file_bytes;  // later checkpoints are written over
    next_sample = mark.next_sample;
    sample_states.resize(next_sample);
    if (directional) sample_d.resize(next_sample);
  }
};

// Forward (directional) and transposed (adjoint) application of the steps that need no
// group system. n_y: lowered states; n_p parameters; n_u inputs per segment. The adjoint
// state lambda is (n_y + 2) x q, the parameter gradient (n_p + n_u S) x q.
void ApplyForward(const SaltationStep& step, int np, int nu, const Matrix& theta, Matrix* d);
void ApplyForward(const ClockStep& step, Matrix* d);
void ApplyForward(const StepStart& step, int ny, Matrix* d);
void ApplyForward(const ProjectionStep& step, int np, const Matrix& theta, Matrix* d);
void ApplyTransposed(const SaltationStep& step, int np, int nu, Matrix* lambda, Matrix* gradient);
void ApplyTransposed(const ClockStep& step, int ny, Matrix* lambda);
void ApplyTransposed(const StepStart& step, int ny, Matrix* lambda);
void ApplyTransposed(const ProjectionStep& step, int np, Matrix* lambda, Matrix* gradient);

}  // namespace moreau::internal
