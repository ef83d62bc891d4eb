// The steps of a run's derivative that need no group system, forward and transposed
// (sensitivity_tape.hpp). Each transposed map is derived line by line from its forward map.
#include "sensitivity_tape.hpp"

#include <stdexcept>
#include <string>

namespace moreau::internal {

CheckpointFile::~CheckpointFile() {
  if (file_ != nullptr) std::fclose(file_);
}

long CheckpointFile::Write(long offset, GroupStep* step) {
  if (file_ == nullptr) {
    file_ = std::tmpfile();
    if (file_ == nullptr) throw std::runtime_error("adjoint: cannot create a checkpoint file");
  }
  const auto write = [&](const Vector& v) {
    if (std::fwrite(v.data(), sizeof(double), static_cast<std::size_t>(v.size()), file_) !=
        static_cast<std::size_t>(v.size())) {
      throw std::runtime_error("adjoint: cannot write the checkpoint file (disk full?)");
    }
  };
  if (std::fseek(file_, offset, SEEK_SET) != 0) {
    throw std::runtime_error("adjoint: cannot seek in the checkpoint file");
  }
  step->file_offset = offset;
  step->w_size = step->w.size();
  step->y_size = step->setup.y_start.size();
  write(step->w);
  write(step->setup.y_start);
  step->w = Vector();
  step->setup.y_start = Vector();
  return offset +
         static_cast<long>(sizeof(double)) * static_cast<long>(step->w_size + step->y_size);
}

void CheckpointFile::Read(GroupStep* step) {
  const auto read = [&](Vector* v, Eigen::Index n) {
    v->resize(n);
    if (std::fread(v->data(), sizeof(double), static_cast<std::size_t>(n), file_) !=
        static_cast<std::size_t>(n)) {
      throw std::runtime_error("adjoint: cannot read the checkpoint file");
    }
  };
  if (file_ == nullptr || std::fseek(file_, step->file_offset, SEEK_SET) != 0) {
    throw std::runtime_error("adjoint: cannot seek in the checkpoint file");
  }
  read(&step->w, step->w_size);
  read(&step->setup.y_start, step->y_size);
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
