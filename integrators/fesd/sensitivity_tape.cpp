// The steps of a run's derivative that need no group system, forward and transposed
// (sensitivity_tape.hpp). Each transposed map is derived line by line from its forward map.
#include "sensitivity_tape.hpp"

#include <stdexcept>
#include <string>

namespace moreau::internal {

long CheckpointFile::Write(long offset, GroupStep* step) {
  step->file_offset = offset;
  step->w_size = step->w.size();
  step->y_size = step->setup.y_start.size();
  offset = file_.Write(offset, step->w.data(), static_cast<std::size_t>(step->w_size));
  offset = file_.Write(offset, step->setup.y_start.data(), static_cast<std::size_t>(step->y_size));
  step->w = Vector();
  step->setup.y_start = Vector();
  return offset;
}

void CheckpointFile::Read(GroupStep* step) {
  step->w.resize(step->w_size);
  step->setup.y_start.resize(step->y_size);
  const long offset = step->file_offset;
  file_.Read(offset, step->w.data(), static_cast<std::size_t>(step->w_size));
  file_.Read(offset + static_cast<long>(sizeof(double)) * static_cast<long>(step->w_size),
             step->setup.y_start.data(), static_cast<std::size_t>(step->y_size));
}

void ApplyForward(const SaltationStep& step, int np, int nu, const Matrix& theta, Matrix* d) {
  const int ny = static_cast<int>(step.jump.size());
  Eigen::RowVectorXd d_iota = step.g_y * d->topRows(ny);
  if (np > 0) d_iota += step.g_p * theta.topRows(np);
  if (nu > 0) d_iota += step.g_u * theta.middleRows(np + nu * step.segment, nu);
  d->topRows(ny) -= step.jump * (d_iota / step.rate);
}

void ApplyTransposed(const SaltationStep& step, int np, int nu, Matrix* lambda, Matrix* gradient) {
  const int ny = static_cast<int>(step.jump.size());
  const Eigen::RowVectorXd c = step.jump.transpose() * lambda->topRows(ny) / step.rate;
  lambda->topRows(ny) -= step.g_y.transpose() * c;
  if (np > 0) gradient->topRows(np) -= step.g_p.transpose() * c;
  if (nu > 0) gradient->middleRows(np + nu * step.segment, nu) -= step.g_u.transpose() * c;
}

void ApplyForward(const ClockStep& step, Matrix* d) {
  const int tau = static_cast<int>(d->rows()) - 2;
  d->row(tau) = step.factor * d->row(step.clock);
}

void ApplyTransposed(const ClockStep& step, int ny, Matrix* lambda) {
  const Eigen::RowVectorXd tau = lambda->row(ny);
  lambda->row(ny).setZero();
  lambda->row(step.clock) += step.factor * tau;
}

void ApplyForward(const StepStart& step, int ny, Matrix* d) {
  const Eigen::RowVectorXd d_tau = d->row(ny) + d->row(ny + 1);
  Eigen::RowVectorXd d_end = d_tau;
  if (step.lands) {
    d_end = step.clock_targets ? Eigen::RowVectorXd(d_tau - d->row(step.clock))
                               : Eigen::RowVectorXd::Zero(d_tau.size());
  }
  d->row(ny) = d_tau - d_end;
  d->row(ny + 1) = d_end;
}

// Outputs tau' = d_tau - d_end, end' = d_end with d_tau = tau + end:
//   not landing:           tau' = 0,      end' = tau + end
//   landing on the clock:  tau' = clock,  end' = tau + end - clock
//   landing (fixed end):   tau' = tau + end, end' = 0
void ApplyTransposed(const StepStart& step, int ny, Matrix* lambda) {
  const Eigen::RowVectorXd tau = lambda->row(ny), end = lambda->row(ny + 1);
  if (!step.lands) {
    lambda->row(ny) = end;
    lambda->row(ny + 1) = end;
  } else if (step.clock_targets) {
    lambda->row(step.clock) += tau - end;
    lambda->row(ny) = end;
    lambda->row(ny + 1) = end;
  } else {
    lambda->row(ny) = tau;
    lambda->row(ny + 1) = tau;
  }
}

void ApplyForward(const ProjectionStep& step, int np, const Matrix& theta, Matrix* d) {
  const int nx = static_cast<int>(step.d_x0.rows());
  const int nu = static_cast<int>(step.d_u.cols());
  Matrix x = step.d_x0 * d->topRows(nx) + step.d_t * d->row(step.clock);
  if (np > 0) x += step.d_p * theta.topRows(np);
  if (nu > 0) x += step.d_u * theta.middleRows(np, nu);  // segment 0
  d->topRows(nx) = x;
}

void ApplyTransposed(const ProjectionStep& step, int np, Matrix* lambda, Matrix* gradient) {
  const int nx = static_cast<int>(step.d_x0.rows());
  const int nu = static_cast<int>(step.d_u.cols());
  const Matrix x = lambda->topRows(nx);
  if (np > 0) gradient->topRows(np) += step.d_p.transpose() * x;
  if (nu > 0) gradient->middleRows(np, nu) += step.d_u.transpose() * x;
  lambda->row(step.clock) += step.d_t.transpose() * x;
  lambda->topRows(nx) = step.d_x0.transpose() * x;
}

}  // namespace moreau::internal
