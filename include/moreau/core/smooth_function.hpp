#pragma once
/// @file
/// SmoothFunction: a model function out = g(x, u, t, p) with exact derivatives.
///
/// Scenes write their functions once, as generic lambdas over a scalar type:
///
///   [](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) { ... }
///
/// where x, u, p are ArgVector<T> (bounds-checked, read-only), t is a T and out is an
/// OutVector<T> of the declared size, zero-initialized. moreau instantiates the lambda with
/// T = double for values, T = Dual<double> for Jacobians and T = Dual<Dual<double>> for
/// weighted Hessians (forward-mode automatic differentiation, chunked in blocks of
/// Dual<double>::kCapacity directions, so there is no limit on the number of inputs), and
/// T = SparsityTracer to detect which inputs each output depends on, for the sparse
/// derivatives (docs/sparse-derivatives.md), and T = Interval for enclosures of the outputs over
/// a box of arguments (interval arithmetic, core/interval.hpp: integrators bound event
/// indicators over a step). Derivatives are therefore exact to round-off; no solver ever uses
/// finite differences.
///
/// Reading x[i] outside the argument's size or writing out[k] outside the declared output
/// size throws std::invalid_argument naming the function, the argument and both sizes.
///
/// Large models whose outputs come in independent groups (one constraint per pair of agents,
/// one velocity per agent) are better written block by block (MakeBlockFunction): a lambda
/// that computes the outputs of one block,
///
///   [](int block, const auto& x, const auto& u, const auto& t, const auto& p, auto& out) { ... }
///
/// Sparse derivatives then evaluate only the blocks of the rows asked for (the near-active
/// constraints), each with as many derivative directions as inputs it reads (no colouring), and
/// in parallel on the threads of a thread pool when one is set (docs/sparse-derivatives.md).
///
/// Evaluation uses per-object workspaces and is not thread-safe; copies are deep (each
/// integrator owns its copies), so separate objects may be used from separate threads.

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "moreau/core/dual.hpp"
#include "moreau/core/interval.hpp"
#include "moreau/core/sparsity_tracer.hpp"
#include "moreau/core/types.hpp"

namespace moreau {

namespace internal {
[[noreturn]] void ThrowArgumentIndex(const std::string& function, const char* argument, int index,
                                     int size);
}  // namespace internal

/// Read-only, bounds-checked view of one argument block (x, u or p) of a model function.
template <class T>
class ArgVector {
 public:
  /// A view of `size` values at `data`, named `argument` of function `function` in messages.
  ArgVector(const T* data, int size, const char* argument, const std::string* function)
      : data_(data), size_(size), argument_(argument), function_(function) {}
  /// Component i; throws std::invalid_argument naming the function if i is out of range.
  const T& operator[](int i) const {
    if (i < 0 || i >= size_) internal::ThrowArgumentIndex(*function_, argument_, i, size_);
    return data_[i];
  }
  /// Component i, as operator[].
  const T& operator()(int i) const { return (*this)[i]; }
  /// Number of components.
  int size() const { return size_; }
  /// The block as an Eigen vector expression (unchecked; sizes are the caller's business).
  Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, 1>> eigen() const {
    return Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, 1>>(data_, size_);
  }

 private:
  const T* data_;
  int size_;
  const char* argument_;
  const std::string* function_;
};

/// Writable, bounds-checked view of a model function's output.
template <class T>
class OutVector {
 public:
  /// A view of the `size` outputs at `data` of function `function` (named in messages).
  OutVector(T* data, int size, const std::string* function)
      : data_(data), size_(size), function_(function) {}
  /// Output i, writable; throws std::invalid_argument naming the function if i is out of range.
  T& operator[](int i) {
    if (i < 0 || i >= size_) internal::ThrowArgumentIndex(*function_, "out", i, size_);
    return data_[i];
  }
  /// Output i, as operator[].
  T& operator()(int i) { return (*this)[i]; }
  /// Number of outputs.
  int size() const { return size_; }
  /// The outputs as an Eigen vector expression (unchecked).
  Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, 1>> eigen() {
    return Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, 1>>(data_, size_);
  }

 private:
  T* data_;
  int size_;
  const std::string* function_;
};

/// Which argument blocks a derivative is taken with respect to. The columns of a Jacobian
/// (and rows/columns of a Hessian) are ordered x, u, t, p, each block present only if
/// selected.
struct Wrt {
  /// Differentiate with respect to the states x.
  bool x = false;
  /// Differentiate with respect to the inputs u.
  bool u = false;
  /// Differentiate with respect to the time t.
  bool t = false;
  /// Differentiate with respect to the parameters p.
  bool p = false;

  /// x only.
  static Wrt X() { return {true, false, false, false}; }
  /// x and t.
  static Wrt XT() { return {true, false, true, false}; }
  /// x, u and t.
  static Wrt XUT() { return {true, true, true, false}; }
  /// Every argument block: x, u, t and p.
  static Wrt All() { return {true, true, true, true}; }
  /// Number of columns for argument sizes (nx, nu, np).
  int Columns(int nx, int nu, int np) const {
    return (x ? nx : 0) + (u ? nu : 0) + (t ? 1 : 0) + (p ? np : 0);
  }
};

namespace internal {
class TypedFunction;
class SparseDerivatives;
class FunctionAnalysis;
struct AnalyzedPattern;
class ThreadPool;
}  // namespace internal

/// Counters of the sparse derivatives of one function object (docs/sparse-derivatives.md).
struct SparseDerivativeStats {
  /// Traced evaluations this object made: the pattern's detection (1 after the first derivative
  /// call of a function without value-dependent branches; 0 for a copy of a function that had
  /// detected it: copies share their original's pattern), and for a point-dependent function
  /// one more at every sparse call.
  int num_detections = 0;
  /// The traced evaluation inspected a value that depends on the inputs (a comparison, isfinite,
  /// ValueOf): the pattern may depend on the point, so it is detected again at every sparse
  /// call and the stored pattern is the union of the patterns seen so far.
  bool point_dependent = false;
  /// Re-detections of a point-dependent function that found new entries (each changes the
  /// pattern of later results and recomputes the colourings).
  int num_pattern_growths = 0;
  /// Colours (compressed directions) and Dual1 evaluations of the last SparseJacobian.
  int jacobian_colors = 0;
  /// Dual1 evaluations of the last SparseJacobian.
  int jacobian_passes = 0;
  /// Colours among the inputs of the nonzero-weight outputs, and Dual2 evaluations, of the last
  /// SparseWeightedHessian.
  int hessian_colors = 0;
  /// Dual2 evaluations of the last SparseWeightedHessian.
  int hessian_passes = 0;
  /// Row subsets whose patterns and colourings are cached (Jacobian and Hessian plans).
  int num_cached_plans = 0;
  /// Memory held by the dual-number workspaces (one Dual1 and, after a Hessian, one Dual2 per
  /// input and per output; sizeof(Dual2) is about 2.4 kB).
  std::size_t workspace_bytes = 0;
};

/// Type-erased smooth model function with exact derivatives (see file comment).
class SmoothFunction {
 public:
  SmoothFunction() = default;
  /// A deep copy (each copy owns its workspaces: copies may be used from separate threads).
  SmoothFunction(const SmoothFunction& other)
      : impl_(other.impl_ ? other.impl_->Clone() : nullptr) {}
  /// A deep copy, as the copy constructor.
  SmoothFunction& operator=(const SmoothFunction& other) {
    if (this != &other) impl_ = other.impl_ ? other.impl_->Clone() : nullptr;
    return *this;
  }
  /// Moves (no copy of the function object).
  SmoothFunction(SmoothFunction&&) noexcept = default;
  /// Move assignment (no copy of the function object).
  SmoothFunction& operator=(SmoothFunction&&) noexcept = default;

  /// True if no function was given (an effect's optional part, or zero dynamics).
  bool empty() const { return impl_ == nullptr; }
  /// The name given at construction (appears in error messages).
  const std::string& name() const;
  /// Number of outputs.
  int num_outputs() const;

  /// out = g(x, u, t, p).
  void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Vector* out) const;
  /// out = g(x, u, t, p) and jac = dg/d(selected blocks), columns ordered as in Wrt.
  void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Wrt wrt, Vector* out, Matrix* jac) const;
  /// hess = sum_k weights_k * d^2 g_k / d(selected)^2 (symmetric).
  void WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                       const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                       Matrix* hess) const;
  /// Sparse exact derivatives, for large models (docs/sparse-derivatives.md).
  ///
  /// out = g(x, u, t, p) (all outputs) and jac = dg/d(selected blocks) as a compressed
  /// column-major sparse matrix (num_outputs() rows; columns ordered as in Wrt). Only the rows
  /// listed in `rows` (sorted, unique; nullptr: every row) are computed; the other rows of jac
  /// are empty. The stored entries are the structurally nonzero ones of those rows (entries
  /// that happen to vanish at this point are stored as zeros), so the pattern of jac is the
  /// same at every point for the same (wrt, rows): a sparse factorization's symbolic analysis
  /// can be reused. For functions made of blocks (MakeBlockFunction) only the blocks holding a
  /// row in `rows` are evaluated: the other entries of out are NaN.
  void SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                      const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                      const std::vector<int>* rows = nullptr) const;
  /// hess = sum over k in `rows` (nullptr: all outputs) of weights_k d^2 g_k / d(selected)^2,
  /// symmetric with both triangles stored, as a compressed column-major sparse matrix whose
  /// pattern is the union of the second-derivative patterns of the outputs in `rows`
  /// (independent of the weights and of the point). Outputs with weight zero cost no
  /// derivative work.
  void SparseWeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                             const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                             SparseMatrix* hess, const std::vector<int>* rows = nullptr) const;
  /// Second derivatives along a direction, one output per row: row k of `rows_matrix` is
  /// (d^2 g_k / d(selected)^2 . direction)^T, i.e. the Jacobian of the directional derivative
  /// grad g_k . direction with the direction held fixed (`direction` has one entry per selected
  /// column). Only the rows in `rows` (nullptr: all) are computed; the pattern of row k is the
  /// set of selected inputs that occur in g_k's second-derivative pairs, the same at every
  /// point and for every direction. Cost: one Dual2 evaluation (16 outer directions, one inner)
  /// per 16 colours of the Hessian colouring of SparseWeightedHessian.
  void SparseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                              const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& direction,
                              SparseMatrix* rows_matrix,
                              const std::vector<int>* rows = nullptr) const;
  /// Enclosure of g over a box: lower_k <= g_k(x, u, t, p) <= upper_k for every x with
  /// x_lower <= x <= x_upper and every t in [t_lower, t_upper] (u and p fixed), by interval
  /// arithmetic (core/interval.hpp). Returns false, with lower and upper unspecified, if no
  /// bound is available: a hand-written function, or a branch (comparison) of the function that
  /// the box does not decide. Only the rows listed in `rows` (sorted, unique; nullptr: every
  /// row) are needed: a function made of blocks (MakeBlockFunction) encloses only the blocks
  /// that hold them (in parallel over the function's threads where they are many), giving the
  /// other rows the entire line (lower -inf, upper +inf), and a branch undecided in the other
  /// blocks does not matter; other functions enclose every row.
  bool Bounds(const ConstVectorRef& x_lower, const ConstVectorRef& x_upper, const ConstVectorRef& u,
              double t_lower, double t_upper, const ConstVectorRef& p, Vector* lower, Vector* upper,
              const std::vector<int>* rows = nullptr) const;
  /// Counters of SparseJacobian and SparseWeightedHessian (all zero for functions without
  /// automatic differentiation).
  SparseDerivativeStats sparse_derivative_stats() const;
  /// True for functions made by MakeSparseStateFunction (hand-written sparse dg/dx).
  bool has_sparse_state_jacobian() const;
  /// out = g and jac_x = dg/dx as a sparse matrix (only if has_sparse_state_jacobian()).
  void SparseStateJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                           const ConstVectorRef& p, Vector* out, SparseMatrix* jac_x) const;
  /// The automatic-differentiation implementation (MakeSmoothFunction, MakeStackedFunction),
  /// or nullptr (empty, or a hand-written sparse Jacobian). Used to compose functions.
  internal::TypedFunction* typed() const;

  /// Concept implemented by the factories (public only for them).
  class Concept {
   public:
    virtual ~Concept() = default;
    /// A deep copy of the implementation.
    virtual std::unique_ptr<Concept> Clone() const = 0;
    /// The function's name.
    virtual const std::string& name() const = 0;
    /// Number of outputs.
    virtual int num_outputs() const = 0;
    /// See SmoothFunction::Evaluate.
    virtual void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                          const ConstVectorRef& p, Vector* out) = 0;
    /// See SmoothFunction::Jacobian.
    virtual void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                          const ConstVectorRef& p, Wrt wrt, Vector* out, Matrix* jac) = 0;
    /// See SmoothFunction::WeightedHessian.
    virtual void WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                 const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                                 Matrix* hess) = 0;
    /// See SmoothFunction::SparseJacobian (default: from the dense Jacobian).
    virtual void SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                                const std::vector<int>* rows);
    /// See SmoothFunction::SparseWeightedHessian (default: from the dense Hessian).
    virtual void SparseWeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                       const ConstVectorRef& p, Wrt wrt,
                                       const ConstVectorRef& weights, SparseMatrix* hess,
                                       const std::vector<int>* rows);
    /// See SmoothFunction::SparseHessianDirection.
    virtual void SparseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                        const ConstVectorRef& p, Wrt wrt,
                                        const ConstVectorRef& direction, SparseMatrix* rows_matrix,
                                        const std::vector<int>* rows);
    /// See SmoothFunction::Bounds.
    virtual bool Bounds(const ConstVectorRef& /*x_lower*/, const ConstVectorRef& /*x_upper*/,
                        const ConstVectorRef& /*u*/, double /*t_lower*/, double /*t_upper*/,
                        const ConstVectorRef& /*p*/, Vector* /*lower*/, Vector* /*upper*/,
                        const std::vector<int>* /*rows*/) {
      return false;
    }
    /// See SmoothFunction::has_sparse_state_jacobian.
    virtual bool has_sparse_state_jacobian() const { return false; }
    /// See SmoothFunction::SparseStateJacobian.
    virtual void SparseStateJacobian(const ConstVectorRef& /*x*/, const ConstVectorRef& /*u*/,
                                     double /*t*/, const ConstVectorRef& /*p*/, Vector* /*out*/,
                                     SparseMatrix* /*jac_x*/) {}
    /// See SmoothFunction::typed.
    virtual internal::TypedFunction* typed() { return nullptr; }
  };
  /// Wraps an implementation (the factories below make them).
  explicit SmoothFunction(std::unique_ptr<Concept> impl) : impl_(std::move(impl)) {}

 private:
  std::unique_ptr<Concept> impl_;
};

namespace internal {

using Dual1 = Dual<double>;
using Dual2 = Dual<Dual<double>>;

// A function evaluated by one routine templated over the scalar type: values (double),
// Jacobians (Dual1, forward mode in chunks of Dual1::kCapacity directions), weighted
// Hessians (Dual2), sparsity patterns (SparsityTracer) and enclosures over boxes (Interval)
// come from the five Call overloads.
// Implemented by generic lambdas (AutoDiffFunction) and by compositions of such functions (stacked
// functions).
class TypedFunction : public SmoothFunction::Concept {
 public:
  TypedFunction(std::string name, int num_outputs);
  ~TypedFunction() override;
  TypedFunction(const TypedFunction&) = delete;
  TypedFunction& operator=(const TypedFunction&) = delete;
  const std::string& name() const override { return name_; }
  int num_outputs() const override { return num_outputs_; }
  TypedFunction* typed() override { return this; }

  void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Vector* out) override;
  void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Wrt wrt, Vector* out, Matrix* jac) override;
  void WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                       const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                       Matrix* hess) override;
  // Sparsity detection, column colouring and compressed forward mode
  // (lib/core/sparse_derivatives.hpp, docs/sparse-derivatives.md).
  void SparseJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                      const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                      const std::vector<int>* rows) override;
  void SparseWeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                             const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                             SparseMatrix* hess, const std::vector<int>* rows) override;
  void SparseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                              const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& direction,
                              SparseMatrix* rows_matrix, const std::vector<int>* rows) override;
  SparseDerivativeStats sparse_derivative_stats() const;
  bool Bounds(const ConstVectorRef& x_lower, const ConstVectorRef& x_upper, const ConstVectorRef& u,
              double t_lower, double t_upper, const ConstVectorRef& p, Vector* lower, Vector* upper,
              const std::vector<int>* rows) override;
  // The enclosure over a box of every input (Bounds' u and p may be intervals here): out[k]
  // for the rows in `rows` (nullptr: all; see SmoothFunction::Bounds), out sized
  // num_outputs(). False if an evaluated block's branch is undecided.
  bool BoxBounds(const Interval* x, int nx, const Interval* u, int nu, const Interval& t,
                 const Interval* p, int np, std::vector<Interval>* out,
                 const std::vector<int>* rows = nullptr);
  // The traced pattern and structure of this function for the sizes of x, u, p
  // (FunctionAnalysis, lib/core/sparse_derivatives.hpp): detected once and shared with every
  // clone, so that copies of a scene or lowered system do not trace again (*detected: this call
  // traced). Structure decides what need not be computed: a weighted Hessian or second
  // derivatives along a direction with respect to blocks the function is affine in are zero (no
  // Dual2 evaluation: a moving set's linear constraint, as S3's floor), and a Jacobian with
  // respect to such blocks is a constant for fixed values of the other inputs (jacobian_cache_).
  const AnalyzedPattern& Analysis(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                  const ConstVectorRef& p, bool* detected = nullptr);
  // Makes `copy` (a clone of this function: same code, same outputs) share this function's
  // analysis (its detected patterns). Every Clone() passes its result through it.
  std::unique_ptr<SmoothFunction::Concept> ShareAnalysis(std::unique_ptr<TypedFunction> copy) const;
  // The analysis this function shares with its clones, and its replacement by another
  // function's of the same code and outputs (MakeStackedFunction: stacks of the same parts).
  const std::shared_ptr<FunctionAnalysis>& shared_analysis() const { return analysis_; }
  void AdoptAnalysis(std::shared_ptr<FunctionAnalysis> analysis) {
    analysis_ = std::move(analysis);
    analyzed_.reset();
  }
  // Dense counterpart of SparseHessianDirection for at most Dual1::kCapacity selected columns:
  // rows(k, j) = (d^2 g_k / d(selected)^2 . direction)_j for every output, from one Dual2
  // evaluation (outer directions: the selected columns; inner: the direction). No sparsity
  // detection or colouring: for small functions that set-up would cost many evaluations. The
  // entries are those of the sparse path, whose colours of one output are distinct columns
  // (the outer derivatives add the same products); its structural zeros are computed zeros.
  void DenseHessianDirection(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                             const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& direction,
                             Matrix* rows);

  // Functions made of blocks (MakeBlockFunction): the outputs of every block (0 for other
  // functions), and the evaluation of one block in the scalar type, its outputs into
  // out[0 .. block_outputs()) (zeroed by the caller).
  virtual int block_outputs() const { return 0; }
  virtual void CallBlock(int block, const double* x, int nx, const double* u, int nu,
                         const double& t, const double* p, int np, double* out);
  virtual void CallBlock(int block, const Dual1* x, int nx, const Dual1* u, int nu, const Dual1& t,
                         const Dual1* p, int np, Dual1* out);
  virtual void CallBlock(int block, const Dual2* x, int nx, const Dual2* u, int nu, const Dual2& t,
                         const Dual2* p, int np, Dual2* out);
  virtual void CallBlock(int block, const Interval* x, int nx, const Interval* u, int nu,
                         const Interval& t, const Interval* p, int np, Interval* out);
  // The threads that sparse derivatives of functions made of blocks may use (null: the
  // calling thread only). The pool must outlive the calls; results do not depend on it.
  void set_thread_pool(ThreadPool* pool) { pool_ = pool; }

  // out[0..num_outputs()) = g(x, u, t, p) in the scalar type; `out` is zeroed by the caller.
  virtual void Call(const double* x, int nx, const double* u, int nu, const double& t,
                    const double* p, int np, double* out) = 0;
  virtual void Call(const Dual1* x, int nx, const Dual1* u, int nu, const Dual1& t, const Dual1* p,
                    int np, Dual1* out) = 0;
  virtual void Call(const Dual2* x, int nx, const Dual2* u, int nu, const Dual2& t, const Dual2* p,
                    int np, Dual2* out) = 0;
  virtual void Call(const SparsityTracer* x, int nx, const SparsityTracer* u, int nu,
                    const SparsityTracer& t, const SparsityTracer* p, int np,
                    SparsityTracer* out) = 0;
  virtual void Call(const Interval* x, int nx, const Interval* u, int nu, const Interval& t,
                    const Interval* p, int np, Interval* out) = 0;

 protected:
  std::string name_;
  int num_outputs_;

 private:
  template <class T>
  struct Space {
    std::vector<T> x, u, p, out;
    T t;
  };
  // Fills the workspace of scalar type T; seed(value, column) returns the seeded scalar for a
  // selected input with derivative column `column`; unselected inputs become constants.
  template <class T, class Seed>
  void SeedInputs(Space<T>* space, const ConstVectorRef& x, const ConstVectorRef& u, double t,
                  const ConstVectorRef& p, Wrt wrt, Seed&& seed);
  Space<Dual1> space1_;
  Space<Interval> interval_space_;
  // BoxBounds of functions made of blocks: the blocks of the rows asked for, and whether each
  // thread's evaluations met an undecided branch (its flags are thread-local).
  std::vector<int> bound_blocks_;
  std::vector<char> bound_undecided_;
  // Made at the first dense WeightedHessian: its scalar t alone is a Dual2 (~2.3 kB), which
  // would make every function object, and every copy of a scene, a large allocation.
  std::unique_ptr<Space<Dual2>> space2_;
  std::shared_ptr<FunctionAnalysis> analysis_;
  std::shared_ptr<const AnalyzedPattern> analyzed_;  // the entry last used
  int detections_ = 0;                               // traces this object made for it
  // The constant dense Jacobian of the last Jacobian call where it is one, keyed by the wrt
  // blocks and the values of the unselected inputs (compared bit for bit); also the values
  // where the function does not depend on the selected inputs at all (JacobianZero).
  struct JacobianCache {
    bool valid = false;
    unsigned wrt_bits = 0;
    int nx = -1, nu = -1, np = -1;
    std::vector<double> key;
    Matrix jacobian;
    bool values_valid = false;
    Vector values;
  };
  JacobianCache jacobian_cache_;
  // Detected patterns, colourings and workspaces; made at the first sparse call and not copied
  // (a copy detects again at its own first sparse call).
  std::unique_ptr<SparseDerivatives> sparse_;
  ThreadPool* pool_ = nullptr;
};

// A TypedFunction whose five Call overloads forward to one template
// Derived::Invoke<T>(x, nx, u, nu, t, p, np, out) (declare TypedFunctionFor<Derived> a friend
// if Invoke is private).
template <class Derived>
class TypedFunctionFor : public TypedFunction {
 public:
  using TypedFunction::TypedFunction;
  void Call(const double* x, int nx, const double* u, int nu, const double& t, const double* p,
            int np, double* out) final {
    static_cast<Derived*>(this)->Invoke(x, nx, u, nu, t, p, np, out);
  }
  void Call(const Dual1* x, int nx, const Dual1* u, int nu, const Dual1& t, const Dual1* p, int np,
            Dual1* out) final {
    static_cast<Derived*>(this)->Invoke(x, nx, u, nu, t, p, np, out);
  }
  void Call(const Dual2* x, int nx, const Dual2* u, int nu, const Dual2& t, const Dual2* p, int np,
            Dual2* out) final {
    static_cast<Derived*>(this)->Invoke(x, nx, u, nu, t, p, np, out);
  }
  void Call(const SparsityTracer* x, int nx, const SparsityTracer* u, int nu,
            const SparsityTracer& t, const SparsityTracer* p, int np, SparsityTracer* out) final {
    static_cast<Derived*>(this)->Invoke(x, nx, u, nu, t, p, np, out);
  }
  void Call(const Interval* x, int nx, const Interval* u, int nu, const Interval& t,
            const Interval* p, int np, Interval* out) final {
    static_cast<Derived*>(this)->Invoke(x, nx, u, nu, t, p, np, out);
  }
};

// Implementation of SmoothFunction for a generic lambda F.
template <class F>
class AutoDiffFunction final : public TypedFunctionFor<AutoDiffFunction<F>> {
  using Base = TypedFunctionFor<AutoDiffFunction<F>>;
  friend Base;

 public:
  AutoDiffFunction(std::string name, int num_outputs, F f)
      : Base(std::move(name), num_outputs), f_(std::move(f)) {}
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return this->ShareAnalysis(
        std::make_unique<AutoDiffFunction>(this->name_, this->num_outputs_, f_));
  }

 private:
  template <class T>
  void Invoke(const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np, T* out) {
    ArgVector<T> xv(x, nx, "x", &this->name_), uv(u, nu, "u", &this->name_),
        pv(p, np, "p", &this->name_);
    OutVector<T> ov(out, this->num_outputs_, &this->name_);
    f_(xv, uv, t, pv, ov);
  }
  F f_;
};

// Implementation of SmoothFunction for a generic lambda F over blocks (MakeBlockFunction).
template <class F>
class BlockFunction final : public TypedFunctionFor<BlockFunction<F>> {
  using Base = TypedFunctionFor<BlockFunction<F>>;
  friend Base;

 public:
  BlockFunction(std::string name, int num_blocks, int block_outputs, F f)
      : Base(std::move(name), num_blocks * block_outputs),
        num_blocks_(num_blocks),
        block_outputs_(block_outputs),
        f_(std::move(f)) {}
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return this->ShareAnalysis(
        std::make_unique<BlockFunction>(this->name_, num_blocks_, block_outputs_, f_));
  }
  int block_outputs() const override { return block_outputs_; }
  void CallBlock(int block, const double* x, int nx, const double* u, int nu, const double& t,
                 const double* p, int np, double* out) override {
    Block(block, x, nx, u, nu, t, p, np, out);
  }
  void CallBlock(int block, const Dual1* x, int nx, const Dual1* u, int nu, const Dual1& t,
                 const Dual1* p, int np, Dual1* out) override {
    Block(block, x, nx, u, nu, t, p, np, out);
  }
  void CallBlock(int block, const Dual2* x, int nx, const Dual2* u, int nu, const Dual2& t,
                 const Dual2* p, int np, Dual2* out) override {
    Block(block, x, nx, u, nu, t, p, np, out);
  }
  void CallBlock(int block, const Interval* x, int nx, const Interval* u, int nu, const Interval& t,
                 const Interval* p, int np, Interval* out) override {
    Block(block, x, nx, u, nu, t, p, np, out);
  }

 private:
  template <class T>
  void Block(int block, const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np,
             T* out) {
    ArgVector<T> xv(x, nx, "x", &this->name_), uv(u, nu, "u", &this->name_),
        pv(p, np, "p", &this->name_);
    OutVector<T> ov(out, block_outputs_, &this->name_);
    f_(block, xv, uv, t, pv, ov);
  }
  template <class T>
  void Invoke(const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np, T* out) {
    for (int b = 0; b < num_blocks_; ++b) {
      Block(b, x, nx, u, nu, t, p, np, out + static_cast<std::ptrdiff_t>(b) * block_outputs_);
    }
  }
  int num_blocks_;
  int block_outputs_;
  F f_;
};

}  // namespace internal

/// Wraps a generic lambda (see file comment) with `num_outputs` outputs. `name` appears in
/// error messages ("function 'wall.c' reads x[2], but x has 2 components").
template <class F>
SmoothFunction MakeSmoothFunction(std::string name, int num_outputs, F f) {
  RequireArgument(num_outputs >= 0, "function '", name,
                  "': number of outputs must be non-negative, got ", num_outputs);
  return SmoothFunction(
      std::make_unique<internal::AutoDiffFunction<F>>(std::move(name), num_outputs, std::move(f)));
}

/// A function made of `num_blocks` >= 0 blocks of `block_outputs` >= 1 outputs each: output k
/// of block b is output b * block_outputs + k, and f(block, x, u, t, p, out) writes the
/// outputs of one block to out[0 .. block_outputs) (zero-initialized; writing beyond throws
/// std::invalid_argument as for MakeSmoothFunction). The blocks must be independent: block b's
/// outputs are computed from its own call alone. Values, dense derivatives and sparsity
/// detection evaluate all blocks in order; sparse derivatives evaluate only the blocks of the
/// rows they are asked for, with one derivative direction per input of the block (forward
/// mode on the block, no colouring), on the thread pool of the lowered system when it has one
/// (docs/sparse-derivatives.md). Use it for models of many small independent parts (the crowd:
/// one block per agent, per pair, per wall constraint).
template <class F>
SmoothFunction MakeBlockFunction(std::string name, int num_blocks, int block_outputs, F f) {
  RequireArgument(num_blocks >= 0, "function '", name,
                  "': number of blocks must be non-negative, got ", num_blocks);
  RequireArgument(block_outputs >= 1, "function '", name,
                  "': outputs per block must be at least 1, got ", block_outputs);
  RequireArgument(static_cast<long long>(num_blocks) * block_outputs <= (1LL << 30), "function '",
                  name, "': ", num_blocks, " blocks of ", block_outputs, " outputs are too many");
  return SmoothFunction(std::make_unique<internal::BlockFunction<F>>(std::move(name), num_blocks,
                                                                     block_outputs, std::move(f)));
}

/// The outputs of `parts` one after the other: g = (g_0, g_1, ...), all of the same arguments
/// (x, u, t, p). Every part must differentiate automatically (MakeSmoothFunction or
/// MakeStackedFunction); an empty part is an error. Used to extend a scene (e.g. by a
/// running-cost state) without rewriting its functions.
SmoothFunction MakeStackedFunction(std::string name, const std::vector<SmoothFunction>& parts);
/// A function with `num_outputs` outputs that are all zero (differentiable like any other).
SmoothFunction MakeZeroFunction(std::string name, int num_outputs);

/// Value of a hand-written function: out = g(x, u, t, p) (out is pre-sized).
using ValueFunction = std::function<void(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                         const ConstVectorRef& p, VectorRef out)>;
/// Hand-written sparse Jacobian dg/dx of a function of the state only.
using SparseJacobianFunction =
    std::function<void(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                       const ConstVectorRef& p, SparseMatrix* jac_x)>;

/// A function of the state only with a hand-written sparse Jacobian, for large models
/// (automatic differentiation gives dense Jacobians). It must not depend on u, t or p: their
/// derivatives are reported as zero. Second derivatives are not available, so such functions
/// may serve as smooth dynamics but not as constraint functions of a moving set.
SmoothFunction MakeSparseStateFunction(std::string name, int num_outputs, ValueFunction value,
                                       SparseJacobianFunction jacobian_x);

}  // namespace moreau
