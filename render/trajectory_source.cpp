#include "render/trajectory_source.hpp"

#include <cerrno>
#include <cstdlib>

#include "moreau/core/error.hpp"

namespace moreau::render {

bool MemorySource::Next(double* t, Vector* x) {
  if (next_ >= trajectory_.size()) return false;
  *t = trajectory_.t[next_];
  *x = trajectory_.x[next_];
  ++next_;
  return true;
}

CsvSource::CsvSource(const std::string& path, const std::vector<std::string>& state_names)
    : path_(path), in_(path), num_states_(static_cast<int>(state_names.size())) {
  RequireArgument(in_.good(), "cannot read '", path, "'");
  RequireArgument(static_cast<bool>(std::getline(in_, line_)), path, ": empty file");
  std::string expected = "t";
  for (const std::string& name : state_names) expected += "," + name;
  const bool matches = line_.compare(0, expected.size(), expected) == 0 &&
                       (line_.size() == expected.size() || line_[expected.size()] == ',');
  RequireArgument(matches, path, ":1: header does not start with t and the view's ",
                  state_names.size(), " states");
}

bool CsvSource::Next(double* t, Vector* x) {
  if (!std::getline(in_, line_)) return false;
  ++line_number_;
  if (x->size() != num_states_) x->resize(num_states_);
  const char* p = line_.c_str();
  for (int column = 0; column <= num_states_; ++column) {
    char* end = nullptr;
    errno = 0;
    const double value = std::strtod(p, &end);
    RequireArgument(end != p && (*end == ',' || *end == '\0') && errno != ERANGE, path_, ":",
                    line_number_, ": expected a number in column ", column + 1);
    if (column == 0) {
      *t = value;
    } else {
      (*x)[column - 1] = value;
    }
    p = *end == ',' ? end + 1 : end;
  }
  return true;
}

Sampler::Sampler(TrajectorySource* source) : source_(source) {}

bool Sampler::At(double t, Vector* x) {
  if (!started_) {
    started_ = true;
    if (!source_->Next(&t_a_, &x_a_)) return false;
    t_b_ = t_a_;
    x_b_ = x_a_;
    done_ = !source_->Next(&t_b_, &x_b_);
  }
  if (x_a_.size() == 0) return false;
  // Advance until t lies in [t_a, t_b] (or the source ends).
  while (!done_ && t_b_ <= t) {
    t_a_ = t_b_;
    std::swap(x_a_, x_b_);
    done_ = !source_->Next(&t_b_, &x_b_);
    if (done_) {
      t_b_ = t_a_;
      x_b_ = x_a_;
    }
  }
  if (t <= t_a_ || t_b_ <= t_a_) {
    *x = t <= t_a_ ? x_a_ : x_b_;
    if (done_) *x = x_a_;
    return true;
  }
  const double s = (t - t_a_) / (t_b_ - t_a_);
  *x = (1.0 - s) * x_a_ + s * x_b_;
  return true;
}

}  // namespace moreau::render
