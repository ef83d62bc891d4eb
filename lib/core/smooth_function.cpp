#include "moreau/core/smooth_function.hpp"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "sparse_derivatives.hpp"
#include "thread_pool.hpp"

namespace moreau {

namespace internal {
void ThrowArgumentIndex(const std::string& function, const char* argument, int index, int size) {
  if (std::string(argument) == "out") {
    ThrowInvalidArgument("function '", function, "' writes out[", index, "], but it declares ",
                         size, " output", size == 1 ? "" : "s");
  }
  ThrowInvalidArgument("function '", function, "' reads ", argument, "[", index, "], but ",
                       argument, " has ", size, " component", size == 1 ? "" : "s");
}
}  // namespace internal

namespace internal {

TypedFunction::TypedFunction(std::string name, int num_outputs)
    : name_(std::move(name)),
      num_outputs_(num_outputs),
      analysis_(std::make_shared<FunctionAnalysis>()) {}

std::unique_ptr<SmoothFunction::Concept> TypedFunction::ShareAnalysis(
    std::unique_ptr<TypedFunction> copy) const {
  copy->analysis_ = analysis_;
  copy->analyzed_ = analyzed_;
  return copy;
}

const AnalyzedPattern& TypedFunction::Analysis(const ConstVectorRef& x, const ConstVectorRef& u,
                                               double t, const ConstVectorRef& p, bool* detected) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  bool traced = false;
  if (analyzed_ == nullptr || !analyzed_->pattern.SameSizes(nx, nu, np)) {
    analyzed_ = analysis_->Find(this, x, u, t, p, &traced);
    if (traced) ++detections_;
  }
  if (detected != nullptr) *detected = traced;
  return *analyzed_;
}

TypedFunction::~TypedFunction() = default;

void TypedFunction::SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                   const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                                   const std::vector<int>* rows) {
  if (!sparse_) sparse_ = std::make_unique<SparseDerivatives>();
  sparse_->Jacobian(this, x, u, t, p, wrt, out, jac, rows, pool_);
}

void TypedFunction::SparseWeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u,
                                          double t, const ConstVectorRef& p, Wrt wrt,
                                          const ConstVectorRef& weights, SparseMatrix* hess,
                                          const std::vector<int>* rows) {
  if (!sparse_) sparse_ = std::make_unique<SparseDerivatives>();
  sparse_->WeightedHessian(this, x, u, t, p, wrt, weights, hess, rows);
}

void TypedFunction::SparseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u,
                                           double t, const ConstVectorRef& p, Wrt wrt,
                                           const ConstVectorRef& direction,
                                           SparseMatrix* rows_matrix,
                                           const std::vector<int>* rows) {
  if (!sparse_) sparse_ = std::make_unique<SparseDerivatives>();
  sparse_->HessianDirection(this, x, u, t, p, wrt, direction, rows_matrix, rows);
}

void TypedFunction::DenseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u,
                                          double t, const ConstVectorRef& p, Wrt wrt,
                                          const ConstVectorRef& direction, Matrix* rows) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  const int columns = wrt.Columns(nx, nu, np);
  MOREAU_ASSERT(columns <= Dual1::kCapacity && direction.size() == columns,
                "dense Hessian direction: too many columns or a direction of the wrong size");
  rows->setZero(num_outputs_, columns);
  if (Analysis(x, u, t, p).structure.HessianZero(wrt)) return;  // affine in the columns
  if (space2_ == nullptr) space2_ = std::make_unique<Space<Dual2>>();
  Space<Dual2>& space2 = *space2_;
  // Selected input `column`: outer derivative direction `column`, inner derivative its
  // direction entry (a constant inner part where that entry is zero, as the sparse path).
  auto seed = [&](double value, int column) {
    const double d = direction[column];
    Dual1 inner(value);
    if (d != 0.0) {
      inner = Dual1(value, 1);
      inner.d(0) = d;
    }
    return Dual2::Variable(inner, columns, column);
  };
  SeedInputs(&space2, x, u, t, p, wrt, seed);
  Call(space2.x.data(), nx, space2.u.data(), nu, space2.t, space2.p.data(), np, space2.out.data());
  for (int k = 0; k < num_outputs_; ++k) {
    const Dual2& value = space2.out[static_cast<std::size_t>(k)];
    for (int j = 0; j < value.size(); ++j) {
      const Dual1& column = value.d(j);
      if (column.size() > 0) (*rows)(k, j) = column.d(0);
    }
  }
}

bool TypedFunction::Bounds(const ConstVectorRef& x_lower, const ConstVectorRef& x_upper,
                           const ConstVectorRef& u, double t_lower, double t_upper,
                           const ConstVectorRef& p, Vector* lower, Vector* upper,
                           const std::vector<int>* rows) {
  MOREAU_ASSERT(x_lower.size() == x_upper.size(), "Bounds: state bounds of different sizes");
  Space<Interval>& space = interval_space_;
  space.x.resize(static_cast<std::size_t>(x_lower.size()));
  space.u.resize(static_cast<std::size_t>(u.size()));
  space.p.resize(static_cast<std::size_t>(p.size()));
  for (Eigen::Index i = 0; i < x_lower.size(); ++i) {
    space.x[static_cast<std::size_t>(i)] = Interval(x_lower[i], x_upper[i]);
  }
  for (Eigen::Index i = 0; i < u.size(); ++i) space.u[static_cast<std::size_t>(i)] = Interval(u[i]);
  for (Eigen::Index i = 0; i < p.size(); ++i) space.p[static_cast<std::size_t>(i)] = Interval(p[i]);
  space.t = Interval(t_lower, t_upper);
  if (!BoxBounds(space.x.data(), static_cast<int>(space.x.size()), space.u.data(),
                 static_cast<int>(space.u.size()), space.t, space.p.data(),
                 static_cast<int>(space.p.size()), &space.out, rows)) {
    return false;
  }
  lower->resize(num_outputs_);
  upper->resize(num_outputs_);
  for (int k = 0; k < num_outputs_; ++k) {
    (*lower)[k] = space.out[static_cast<std::size_t>(k)].lower();
    (*upper)[k] = space.out[static_cast<std::size_t>(k)].upper();
  }
  return true;
}

bool TypedFunction::BoxBounds(const Interval* x, int nx, const Interval* u, int nu,
                              const Interval& t, const Interval* p, int np,
                              std::vector<Interval>* out, const std::vector<int>* rows) {
  const int per_block = block_outputs();
  if (rows == nullptr || per_block == 0) {
    out->assign(static_cast<std::size_t>(num_outputs_), Interval(0.0));
    IntervalFlags& flags = CurrentIntervalFlags();
    flags = IntervalFlags{};
    Call(x, nx, u, nu, t, p, np, out->data());
    const bool decided = !flags.undecided;
    flags = IntervalFlags{};
    return decided;
  }
  // A function made of blocks: the blocks that hold the rows (rows sorted, so blocks are met in
  // order); the other outputs are the entire line (no bound known).
  out->assign(static_cast<std::size_t>(num_outputs_), Interval::Entire());
  std::vector<int>& blocks = bound_blocks_;
  blocks.clear();
  blocks.reserve(static_cast<std::size_t>(num_outputs_ / per_block));  // once: no allocation later
  for (const int row : *rows) {
    const int block = row / per_block;
    if (blocks.empty() || blocks.back() != block) blocks.push_back(block);
  }
  const int num_blocks = static_cast<int>(blocks.size());
  // Threads where the blocks are many. A block's enclosure costs tens of nanoseconds, a tenth of
  // its Jacobian, and a crossing search encloses over many sub-boxes per step: with the block
  // Jacobians' threshold, the crowd of 1000 (about 3000 enclosed blocks per call) ran 10% longer
  // on two threads than on one (`moreau run crowd:N=1000 --h 0.05 --threads T`), so enclosures
  // go parallel from 8 times as many blocks. Each block writes its own outputs, so results do
  // not depend on the threads.
  constexpr int kParallelMinEnclosureBlocks = 8 * kParallelMinBlocks;
  const int threads =
      pool_ != nullptr && num_blocks >= kParallelMinEnclosureBlocks ? pool_->threads() : 1;
  bound_undecided_.assign(static_cast<std::size_t>(threads), 0);
  auto body = [&](int begin, int end, int thread) {
    IntervalFlags& flags = CurrentIntervalFlags();  // this thread's
    flags = IntervalFlags{};
    for (int b = begin; b < end; ++b) {
      Interval* block_out =
          out->data() +
          static_cast<std::ptrdiff_t>(blocks[static_cast<std::size_t>(b)]) * per_block;
      std::fill(block_out, block_out + per_block, Interval(0.0));
      CallBlock(blocks[static_cast<std::size_t>(b)], x, nx, u, nu, t, p, np, block_out);
    }
    // A thread may run several chunks: any undecided one makes the enclosure unavailable.
    if (flags.undecided) bound_undecided_[static_cast<std::size_t>(thread)] = 1;
    flags = IntervalFlags{};
  };
  if (threads > 1) {
    pool_->ParallelFor(num_blocks, body);
  } else {
    body(0, num_blocks, 0);
  }
  return std::find(bound_undecided_.begin(), bound_undecided_.end(), 1) == bound_undecided_.end();
}

// Only functions made of blocks (block_outputs() > 0) are evaluated block by block.
void TypedFunction::CallBlock(int, const double*, int, const double*, int, const double&,
                              const double*, int, double*) {
  MOREAU_ASSERT(false, "CallBlock of a function that is not made of blocks");
}
void TypedFunction::CallBlock(int, const Dual1*, int, const Dual1*, int, const Dual1&, const Dual1*,
                              int, Dual1*) {
  MOREAU_ASSERT(false, "CallBlock of a function that is not made of blocks");
}
void TypedFunction::CallBlock(int, const Dual2*, int, const Dual2*, int, const Dual2&, const Dual2*,
                              int, Dual2*) {
  MOREAU_ASSERT(false, "CallBlock of a function that is not made of blocks");
}
void TypedFunction::CallBlock(int, const Interval*, int, const Interval*, int, const Interval&,
                              const Interval*, int, Interval*) {
  MOREAU_ASSERT(false, "CallBlock of a function that is not made of blocks");
}

SparseDerivativeStats TypedFunction::sparse_derivative_stats() const {
  SparseDerivativeStats stats = sparse_ ? sparse_->stats() : SparseDerivativeStats{};
  stats.num_detections += detections_;
  return stats;
}

void TypedFunction::Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                             const ConstVectorRef& p, Vector* out) {
  out->setZero(num_outputs_);
  Call(x.data(), static_cast<int>(x.size()), u.data(), static_cast<int>(u.size()), t, p.data(),
       static_cast<int>(p.size()), out->data());
}

template <class T, class Seed>
void TypedFunction::SeedInputs(Space<T>* space, const ConstVectorRef& x, const ConstVectorRef& u,
                               double t, const ConstVectorRef& p, Wrt wrt, Seed&& seed) {
  // Sized once (the sizes do not change between calls of one function).
  auto fit = [](std::vector<T>* v, Eigen::Index n) {
    if (v->size() != static_cast<std::size_t>(n)) v->resize(static_cast<std::size_t>(n));
  };
  fit(&space->x, x.size());
  fit(&space->u, u.size());
  fit(&space->p, p.size());
  fit(&space->out, num_outputs_);
  for (T& value : space->out) value = T(0.0);
  int column = 0;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    space->x[static_cast<std::size_t>(i)] = wrt.x ? seed(x[i], column++) : T(x[i]);
  }
  for (Eigen::Index i = 0; i < u.size(); ++i) {
    space->u[static_cast<std::size_t>(i)] = wrt.u ? seed(u[i], column++) : T(u[i]);
  }
  space->t = wrt.t ? seed(t, column++) : T(t);
  for (Eigen::Index i = 0; i < p.size(); ++i) {
    space->p[static_cast<std::size_t>(i)] = wrt.p ? seed(p[i], column++) : T(p[i]);
  }
}

void TypedFunction::Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                             const ConstVectorRef& p, Wrt wrt, Vector* out, Matrix* jac) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  const int columns = wrt.Columns(nx, nu, np);
  out->resize(num_outputs_);
  // A Jacobian that does not depend on the selected inputs (JacobianConstant) is computed once
  // per set of values of the other inputs; the values come from an evaluation in Dual1
  // constants, whose arithmetic is that of the seeded evaluation's values.
  const FunctionStructure& structure = Analysis(x, u, t, p).structure;
  const bool constant = columns > 0 && structure.JacobianConstant(wrt);
  // Values that do not depend on the selected inputs are cached with the Jacobian.
  const bool zero = constant && structure.JacobianZero(wrt);
  const unsigned bits = WrtBits(wrt);
  JacobianCache& cache = jacobian_cache_;
  if (constant) {
    // The unselected inputs, in the order x, u, t, p, against the key (bit for bit).
    bool same =
        cache.valid && cache.wrt_bits == bits && cache.nx == nx && cache.nu == nu && cache.np == np;
    std::size_t next = 0;
    auto compare = [&](const double* values, Eigen::Index size) {
      for (Eigen::Index i = 0; same && i < size; ++i, ++next) {
        same = std::bit_cast<std::uint64_t>(values[i]) ==
               std::bit_cast<std::uint64_t>(cache.key[next]);
      }
    };
    if (same && !wrt.x) compare(x.data(), x.size());
    if (same && !wrt.u) compare(u.data(), u.size());
    if (same && !wrt.t) compare(&t, 1);
    if (same && !wrt.p) compare(p.data(), p.size());
    if (same && zero && cache.values_valid) {
      *out = cache.values;
      *jac = cache.jacobian;
      return;
    }
    if (same) {
      SeedInputs(&space1_, x, u, t, p, wrt, [](double value, int) { return Dual1(value); });
      Call(space1_.x.data(), nx, space1_.u.data(), nu, space1_.t, space1_.p.data(), np,
           space1_.out.data());
      for (int k = 0; k < num_outputs_; ++k) {
        (*out)[k] = space1_.out[static_cast<std::size_t>(k)].value();
      }
      *jac = cache.jacobian;
      return;
    }
  }
  jac->setZero(num_outputs_, columns);
  constexpr int kChunk = Dual1::kCapacity;
  // At least one pass, so that the value is computed even with no selected column.
  for (int first = 0; first == 0 || first < columns; first += kChunk) {
    const int chunk = std::min(kChunk, columns - first);
    auto seed = [&](double value, int column) {
      if (column >= first && column < first + chunk) {
        return Dual1::Variable(value, chunk, column - first);
      }
      return Dual1(value);
    };
    SeedInputs(&space1_, x, u, t, p, wrt, seed);
    Call(space1_.x.data(), nx, space1_.u.data(), nu, space1_.t, space1_.p.data(), np,
         space1_.out.data());
    for (int k = 0; k < num_outputs_; ++k) {
      const Dual1& value = space1_.out[static_cast<std::size_t>(k)];
      if (first == 0) (*out)[k] = value.value();
      for (int i = 0; i < value.size(); ++i) (*jac)(k, first + i) = value.d(i);
    }
  }
  if (constant) {
    cache.valid = true;
    cache.wrt_bits = bits;
    cache.nx = nx;
    cache.nu = nu;
    cache.np = np;
    cache.key.clear();
    auto append = [&cache](const double* values, Eigen::Index size) {
      cache.key.insert(cache.key.end(), values, values + size);
    };
    if (!wrt.x) append(x.data(), x.size());
    if (!wrt.u) append(u.data(), u.size());
    if (!wrt.t) append(&t, 1);
    if (!wrt.p) append(p.data(), p.size());
    cache.jacobian = *jac;
    cache.values_valid = zero;
    if (zero) cache.values = *out;
  }
}

void TypedFunction::WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                    const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                                    Matrix* hess) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  const int columns = wrt.Columns(nx, nu, np);
  hess->setZero(columns, columns);
  // Affine in the selected blocks (a moving set's linear constraint, as S3's floor): zero.
  if (Analysis(x, u, t, p).structure.HessianZero(wrt)) return;
  if (space2_ == nullptr) space2_ = std::make_unique<Space<Dual2>>();
  Space<Dual2>& space2 = *space2_;
  constexpr int kChunk = Dual1::kCapacity;
  // Outer level seeds rows [row0, row0 + rows), inner level columns [col0, col0 + cols).
  for (int row0 = 0; row0 < columns; row0 += kChunk) {
    const int rows = std::min(kChunk, columns - row0);
    for (int col0 = 0; col0 < columns; col0 += kChunk) {
      const int cols = std::min(kChunk, columns - col0);
      auto seed = [&](double value, int column) {
        const Dual1 inner = (column >= col0 && column < col0 + cols)
                                ? Dual1::Variable(value, cols, column - col0)
                                : Dual1(value);
        if (column >= row0 && column < row0 + rows) {
          return Dual2::Variable(inner, rows, column - row0);
        }
        return Dual2(inner);
      };
      SeedInputs(&space2, x, u, t, p, wrt, seed);
      Call(space2.x.data(), nx, space2.u.data(), nu, space2.t, space2.p.data(), np,
           space2.out.data());
      for (int k = 0; k < num_outputs_; ++k) {
        const Dual2& value = space2.out[static_cast<std::size_t>(k)];
        if (weights[k] == 0.0) continue;
        for (int i = 0; i < value.size(); ++i) {
          const Dual1& row = value.d(i);
          for (int j = 0; j < row.size(); ++j) {
            (*hess)(row0 + i, col0 + j) += weights[k] * row.d(j);
          }
        }
      }
    }
  }
}

namespace {

// The outputs of several typed functions one after the other.
class StackedFunction final : public TypedFunctionFor<StackedFunction> {
  friend TypedFunctionFor<StackedFunction>;

 public:
  StackedFunction(std::string name, std::vector<SmoothFunction> parts, int num_outputs)
      : TypedFunctionFor(std::move(name), num_outputs), parts_(std::move(parts)) {}
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return ShareAnalysis(std::make_unique<StackedFunction>(name_, parts_, num_outputs_));
  }

 private:
  template <class T>
  void Invoke(const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np, T* out) {
    for (const SmoothFunction& part : parts_) {
      part.typed()->Call(x, nx, u, nu, t, p, np, out);
      out += part.num_outputs();
    }
  }
  std::vector<SmoothFunction> parts_;
};

// No outputs to write: all zero.
class ZeroFunction final : public TypedFunctionFor<ZeroFunction> {
  friend TypedFunctionFor<ZeroFunction>;

 public:
  using TypedFunctionFor::TypedFunctionFor;
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return ShareAnalysis(std::make_unique<ZeroFunction>(name_, num_outputs_));
  }

 private:
  template <class T>
  void Invoke(const T*, int, const T*, int, const T&, const T*, int, T*) {}
};

}  // namespace

}  // namespace internal

namespace internal {
namespace {

// The analyses of stacked functions by their parts' analyses, in order. Parts that share
// analyses are clones of the same functions (TypedFunction::ShareAnalysis), so two stacks of
// such parts compute the same outputs: the later shares the earlier's analysis instead of
// tracing its pattern again (a switching effect's surfaces and mode fields are stacked anew
// at every lowering, so once per run of a scene). An entry is kept while its parts' analyses
// live (the scene's functions and their clones hold them) and dropped at a later call once
// one of them has died (an address in a key is then no longer trusted).
class StackedAnalyses {
 public:
  std::shared_ptr<FunctionAnalysis> For(const std::vector<std::shared_ptr<FunctionAnalysis>>& parts,
                                        const std::shared_ptr<FunctionAnalysis>& fresh) {
    std::vector<const FunctionAnalysis*> key;
    for (const auto& part : parts) key.push_back(part.get());
    const std::lock_guard<std::mutex> lock(mutex_);
    std::erase_if(entries_, [](const auto& entry) {
      return std::any_of(entry.second.parts.begin(), entry.second.parts.end(),
                         [](const auto& part) { return part.expired(); });
    });
    auto found = entries_.find(key);
    if (found != entries_.end()) return found->second.stacked;
    Entry& entry = entries_[key];
    entry.parts.assign(parts.begin(), parts.end());
    entry.stacked = fresh;
    return fresh;
  }

 private:
  struct Entry {
    std::vector<std::weak_ptr<FunctionAnalysis>> parts;
    std::shared_ptr<FunctionAnalysis> stacked;
  };
  std::mutex mutex_;
  std::map<std::vector<const FunctionAnalysis*>, Entry> entries_;
};

StackedAnalyses& TheStackedAnalyses() {
  static StackedAnalyses analyses;
  return analyses;
}

}  // namespace
}  // namespace internal

SmoothFunction MakeStackedFunction(std::string name, const std::vector<SmoothFunction>& parts) {
  int outputs = 0;
  std::vector<std::shared_ptr<internal::FunctionAnalysis>> part_analyses;
  for (const SmoothFunction& part : parts) {
    RequireArgument(part.typed() != nullptr, "stacked function '", name, "': part '", part.name(),
                    "' is empty or has a hand-written Jacobian; only automatically "
                    "differentiated functions can be stacked");
    outputs += part.num_outputs();
    part_analyses.push_back(part.typed()->shared_analysis());
  }
  auto stacked = std::make_unique<internal::StackedFunction>(std::move(name), parts, outputs);
  stacked->AdoptAnalysis(
      internal::TheStackedAnalyses().For(part_analyses, stacked->shared_analysis()));
  return SmoothFunction(std::move(stacked));
}

SmoothFunction MakeZeroFunction(std::string name, int num_outputs) {
  RequireArgument(num_outputs >= 0, "function '", name,
                  "': number of outputs must be non-negative, got ", num_outputs);
  return SmoothFunction(std::make_unique<internal::ZeroFunction>(std::move(name), num_outputs));
}

internal::TypedFunction* SmoothFunction::typed() const { return impl_ ? impl_->typed() : nullptr; }

namespace {
const std::string kEmptyName = "<none>";
void RequireNonEmpty(const SmoothFunction& f) {
  MOREAU_ASSERT(!f.empty(), "evaluating an empty SmoothFunction");
}
}  // namespace

const std::string& SmoothFunction::name() const { return impl_ ? impl_->name() : kEmptyName; }

int SmoothFunction::num_outputs() const { return impl_ ? impl_->num_outputs() : 0; }

void SmoothFunction::Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                              const ConstVectorRef& p, Vector* out) const {
  RequireNonEmpty(*this);
  impl_->Evaluate(x, u, t, p, out);
}

void SmoothFunction::Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                              const ConstVectorRef& p, Wrt wrt, Vector* out, Matrix* jac) const {
  RequireNonEmpty(*this);
  impl_->Jacobian(x, u, t, p, wrt, out, jac);
}

void SmoothFunction::WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                     const ConstVectorRef& p, Wrt wrt,
                                     const ConstVectorRef& weights, Matrix* hess) const {
  RequireNonEmpty(*this);
  RequireArgument(weights.size() == impl_->num_outputs(), "function '", impl_->name(),
                  "': Hessian weights need ", impl_->num_outputs(), " entries, got ",
                  weights.size());
  impl_->WeightedHessian(x, u, t, p, wrt, weights, hess);
}

void SmoothFunction::SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                    const ConstVectorRef& p, Wrt wrt, Vector* out,
                                    SparseMatrix* jac, const std::vector<int>* rows) const {
  RequireNonEmpty(*this);
  impl_->SparseJacobian(x, u, t, p, wrt, out, jac, rows);
}

void SmoothFunction::SparseWeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u,
                                           double t, const ConstVectorRef& p, Wrt wrt,
                                           const ConstVectorRef& weights, SparseMatrix* hess,
                                           const std::vector<int>* rows) const {
  RequireNonEmpty(*this);
  RequireArgument(weights.size() == impl_->num_outputs(), "function '", impl_->name(),
                  "': Hessian weights need ", impl_->num_outputs(), " entries, got ",
                  weights.size());
  impl_->SparseWeightedHessian(x, u, t, p, wrt, weights, hess, rows);
}

void SmoothFunction::SparseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u,
                                            double t, const ConstVectorRef& p, Wrt wrt,
                                            const ConstVectorRef& direction,
                                            SparseMatrix* rows_matrix,
                                            const std::vector<int>* rows) const {
  RequireNonEmpty(*this);
  RequireArgument(
      direction.size() == wrt.Columns(static_cast<int>(x.size()), static_cast<int>(u.size()),
                                      static_cast<int>(p.size())),
      "function '", impl_->name(), "': direction has ", direction.size(),
      " entries, expected one per selected column");
  impl_->SparseHessianDirection(x, u, t, p, wrt, direction, rows_matrix, rows);
}

// Reference implementation from the dense derivatives: row k from the Hessian of output k
// alone (every selected column stored). Implementations that detect sparsity override it.
void SmoothFunction::Concept::SparseHessianDirection(
    const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p, Wrt wrt,
    const ConstVectorRef& direction, SparseMatrix* rows_matrix, const std::vector<int>* rows) {
  const int m = num_outputs();
  std::vector<int> all;
  if (rows == nullptr) {
    for (int k = 0; k < m; ++k) all.push_back(k);
    rows = &all;
  }
  std::vector<Eigen::Triplet<double, int>> entries;
  Vector weights = Vector::Zero(m);
  Matrix hessian;
  for (int k : *rows) {
    weights.setZero();
    weights[k] = 1.0;
    WeightedHessian(x, u, t, p, wrt, weights, &hessian);
    const Vector row = hessian * direction;
    for (Eigen::Index j = 0; j < row.size(); ++j) entries.emplace_back(k, j, row[j]);
  }
  rows_matrix->resize(m, direction.size());
  rows_matrix->setFromTriplets(entries.begin(), entries.end());
  rows_matrix->makeCompressed();
}

// Reference implementation from the dense derivatives: every entry of the selected rows is
// stored (a dense pattern, trivially the same at every point). Implementations that detect
// the sparsity of the function override it.
void SmoothFunction::Concept::SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u,
                                             double t, const ConstVectorRef& p, Wrt wrt,
                                             Vector* out, SparseMatrix* jac,
                                             const std::vector<int>* rows) {
  Matrix dense;
  Jacobian(x, u, t, p, wrt, out, &dense);
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int j = 0; j < dense.cols(); ++j) {
    if (rows == nullptr) {
      for (int i = 0; i < dense.rows(); ++i) entries.emplace_back(i, j, dense(i, j));
    } else {
      for (int i : *rows) entries.emplace_back(i, j, dense(i, j));
    }
  }
  jac->resize(dense.rows(), dense.cols());
  jac->setFromTriplets(entries.begin(), entries.end());
  jac->makeCompressed();
}

void SmoothFunction::Concept::SparseWeightedHessian(
    const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p, Wrt wrt,
    const ConstVectorRef& weights, SparseMatrix* hess, const std::vector<int>* rows) {
  Vector selected = weights;
  if (rows != nullptr) {
    selected.setZero();
    for (int k : *rows) selected[k] = weights[k];
  }
  Matrix dense;
  WeightedHessian(x, u, t, p, wrt, selected, &dense);
  hess->resize(dense.rows(), dense.cols());
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int j = 0; j < dense.cols(); ++j) {
    for (int i = 0; i < dense.rows(); ++i) entries.emplace_back(i, j, dense(i, j));
  }
  hess->setFromTriplets(entries.begin(), entries.end());
  hess->makeCompressed();
}

SparseDerivativeStats SmoothFunction::sparse_derivative_stats() const {
  const internal::TypedFunction* f = typed();
  return f != nullptr ? f->sparse_derivative_stats() : SparseDerivativeStats{};
}

bool SmoothFunction::Bounds(const ConstVectorRef& x_lower, const ConstVectorRef& x_upper,
                            const ConstVectorRef& u, double t_lower, double t_upper,
                            const ConstVectorRef& p, Vector* lower, Vector* upper,
                            const std::vector<int>* rows) const {
  RequireNonEmpty(*this);
  return impl_->Bounds(x_lower, x_upper, u, t_lower, t_upper, p, lower, upper, rows);
}

bool SmoothFunction::has_sparse_state_jacobian() const {
  return impl_ && impl_->has_sparse_state_jacobian();
}

void SmoothFunction::SparseStateJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                         const ConstVectorRef& p, Vector* out,
                                         SparseMatrix* jac_x) const {
  RequireNonEmpty(*this);
  MOREAU_ASSERT(impl_->has_sparse_state_jacobian(), "function has no sparse Jacobian");
  impl_->SparseStateJacobian(x, u, t, p, out, jac_x);
}

namespace {
class SparseStateFunction final : public SmoothFunction::Concept {
 public:
  SparseStateFunction(std::string name, int num_outputs, ValueFunction value,
                      SparseJacobianFunction jacobian_x)
      : name_(std::move(name)),
        num_outputs_(num_outputs),
        value_(std::move(value)),
        jacobian_x_(std::move(jacobian_x)) {}
  std::unique_ptr<Concept> Clone() const override {
    return std::make_unique<SparseStateFunction>(name_, num_outputs_, value_, jacobian_x_);
  }
  const std::string& name() const override { return name_; }
  int num_outputs() const override { return num_outputs_; }
  void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Vector* out) override {
    out->setZero(num_outputs_);
    value_(x, u, t, p, *out);
  }
  void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Wrt wrt, Vector* out, Matrix* jac) override {
    SparseMatrix jx;
    SparseStateJacobian(x, u, t, p, out, &jx);
    const int nx = static_cast<int>(x.size());
    jac->setZero(num_outputs_,
                 wrt.Columns(nx, static_cast<int>(u.size()), static_cast<int>(p.size())));
    if (wrt.x) jac->leftCols(nx) = Matrix(jx);
  }
  void WeightedHessian(const ConstVectorRef&, const ConstVectorRef&, double, const ConstVectorRef&,
                       Wrt, const ConstVectorRef&, Matrix*) override {
    ThrowInvalidArgument("function '", name_,
                         "' has a hand-written Jacobian only; second derivatives are not "
                         "available (write it as a generic lambda instead)");
  }
  // The hand-written dg/dx in the x columns; u, t and p columns are empty (g depends on x only).
  void SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                      const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                      const std::vector<int>* rows) override {
    SparseMatrix jx;
    SparseStateJacobian(x, u, t, p, out, &jx);
    const int nx = static_cast<int>(x.size());
    jac->resize(num_outputs_,
                wrt.Columns(nx, static_cast<int>(u.size()), static_cast<int>(p.size())));
    std::vector<char> keep(static_cast<std::size_t>(num_outputs_), rows == nullptr ? 1 : 0);
    if (rows != nullptr) {
      for (int k : *rows) keep[static_cast<std::size_t>(k)] = 1;
    }
    std::vector<Eigen::Triplet<double, int>> entries;
    if (wrt.x) {
      for (int j = 0; j < jx.outerSize(); ++j) {
        for (SparseMatrix::InnerIterator it(jx, j); it; ++it) {
          if (keep[static_cast<std::size_t>(it.row())])
            entries.emplace_back(it.row(), j, it.value());
        }
      }
    }
    jac->setFromTriplets(entries.begin(), entries.end());
    jac->makeCompressed();
  }
  bool has_sparse_state_jacobian() const override { return true; }
  void SparseStateJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                           const ConstVectorRef& p, Vector* out, SparseMatrix* jac_x) override {
    Evaluate(x, u, t, p, out);
    jac_x->resize(num_outputs_, x.size());
    jacobian_x_(x, u, t, p, jac_x);
    RequireArgument(jac_x->rows() == num_outputs_ && jac_x->cols() == x.size(), "function '", name_,
                    "': sparse Jacobian must be ", num_outputs_, " x ", x.size(), ", got ",
                    jac_x->rows(), " x ", jac_x->cols());
    jac_x->makeCompressed();
  }

 private:
  std::string name_;
  int num_outputs_;
  ValueFunction value_;
  SparseJacobianFunction jacobian_x_;
};
}  // namespace

SmoothFunction MakeSparseStateFunction(std::string name, int num_outputs, ValueFunction value,
                                       SparseJacobianFunction jacobian_x) {
  RequireArgument(num_outputs >= 0, "function '", name,
                  "': number of outputs must be non-negative, got ", num_outputs);
  RequireArgument(value && jacobian_x, "function '", name,
                  "': value and Jacobian callbacks are required");
  return SmoothFunction(std::make_unique<SparseStateFunction>(
      std::move(name), num_outputs, std::move(value), std::move(jacobian_x)));
}

}  // namespace moreau
