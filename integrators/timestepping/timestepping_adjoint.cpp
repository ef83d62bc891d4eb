// The kept step transfers of a time-stepping run and their reverse sweep (timestepping_tape.hpp).
#include <utility>

#include "../common/sensitivity_arguments.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "timestepping_tape.hpp"

namespace moreau {
namespace internal {

void TimeSteppingTape::Add(int segment, const Matrix& transfer) {
  Transfer kept;
  kept.segment = segment;
  const std::size_t size = sizeof(double) * static_cast<std::size_t>(transfer.size());
  if (memory_limit > 0 && bytes + size > memory_limit) {
    if (!file) file = std::make_unique<SpillFile>();
    kept.file_offset = file_bytes;
    file_bytes =
        file->Write(file_bytes, transfer.data(), static_cast<std::size_t>(transfer.size()));
  } else {
    kept.matrix = transfer;
    bytes += size;
  }
  transfers.push_back(std::move(kept));
}

void TimeSteppingTape::Sweep(const Matrix& final_weights, const Matrix& sample_weights,
                             Matrix* lowered, Matrix* theta) const {
  const int samples = static_cast<int>(sample_positions.size());
  Matrix final_shaped, sample_shaped;
  const Eigen::Index q = ShapedAdjointWeights(final_weights, sample_weights, nx, ny, samples,
                                              &final_shaped, &sample_shaped);
  const int n_theta = np + nu * segments;
  Matrix lambda = Matrix::Zero(ny, q);
  if (final_shaped.size() > 0) lambda.topRows(final_shaped.rows()) = final_shaped;
  Matrix gradient = Matrix::Zero(n_theta, q);
  // Samples are added where the sweep passes their state (after their last transfer).
  int sample = samples - 1;
  const auto add_samples_at = [&](std::size_t position) {
    for (; sample >= 0 && sample_positions[static_cast<std::size_t>(sample)] == position;
         --sample) {
      if (sample_shaped.size() > 0) {
        lambda.topRows(sample_shaped.rows()) += sample_shaped.middleCols(sample * q, q);
      }
    }
  };
  Matrix loaded;
  for (std::size_t k = transfers.size(); k-- > 0;) {
    add_samples_at(k + 1);
    const Transfer& kept = transfers[k];
    const Matrix* t = &kept.matrix;
    if (kept.file_offset >= 0) {
      loaded.resize(ny, ny + np + nu);
      file->Read(kept.file_offset, loaded.data(), static_cast<std::size_t>(loaded.size()));
      t = &loaded;
    }
    if (np > 0) gradient.topRows(np) += t->middleCols(ny, np).transpose() * lambda;
    if (nu > 0) {
      gradient.middleRows(np + nu * kept.segment, nu) += t->rightCols(nu).transpose() * lambda;
    }
    lambda = t->leftCols(ny).transpose() * lambda;
  }
  add_samples_at(0);
  lowered->resize(q, ny + n_theta);
  *lowered << lambda.transpose(), gradient.transpose();
  theta->resize(q, nx + n_theta);
  *theta << lambda.topRows(nx).transpose(), gradient.transpose();
}

}  // namespace internal

TimeSteppingAdjoint::TimeSteppingAdjoint(std::shared_ptr<const internal::TimeSteppingTape> tape)
    : tape_(std::move(tape)) {}

TimeSteppingGradient TimeSteppingAdjoint::Sweep(const Matrix& final_weights,
                                                const Matrix& sample_weights) const {
  const RunClock run_clock;
  TimeSteppingGradient out;
  tape_->Sweep(final_weights, sample_weights, &out.lowered, &out.theta);
  out.cpu_seconds = run_clock.CpuSeconds();
  return out;
}

}  // namespace moreau
