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
/// Dual<double>::kCapacity directions, so there is no limit on the number of inputs).
/// Derivatives are therefore exact to round-off; no solver ever uses finite differences.
///
/// Reading x[i] outside the argument's size or writing out[k] outside the declared output
/// size throws std::invalid_argument naming the function, the argument and both sizes.
///
/// Evaluation uses per-object workspaces and is not thread-safe; copies are deep (each
/// integrator owns its copies), so separate objects may be used from separate threads.

#include <functional>
#include <memory>
#include <string>
#include <utility>

#include "moreau/core/dual.hpp"
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
  ArgVector(const T* data, int size, const char* argument, const std::string* function)
      : data_(data), size_(size), argument_(argument), function_(function) {}
  const T& operator[](int i) const {
    if (i < 0 || i >= size_) internal::ThrowArgumentIndex(*function_, argument_, i, size_);
    return data_[i];
  }
  const T& operator()(int i) const { return (*this)[i]; }
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
  OutVector(T* data, int size, const std::string* function)
      : data_(data), size_(size), function_(function) {}
  T& operator[](int i) {
    if (i < 0 || i >= size_) internal::ThrowArgumentIndex(*function_, "out", i, size_);
    return data_[i];
  }
  T& operator()(int i) { return (*this)[i]; }
  int size() const { return size_; }
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
  bool x = false;
  bool u = false;
  bool t = false;
  bool p = false;

  static Wrt X() { return {true, false, false, false}; }
  static Wrt XT() { return {true, false, true, false}; }
  static Wrt XUT() { return {true, true, true, false}; }
  static Wrt All() { return {true, true, true, true}; }
  /// Number of columns for argument sizes (nx, nu, np).
  int Columns(int nx, int nu, int np) const {
    return (x ? nx : 0) + (u ? nu : 0) + (t ? 1 : 0) + (p ? np : 0);
  }
};

/// Type-erased smooth model function with exact derivatives (see file comment).
class SmoothFunction {
 public:
  SmoothFunction() = default;
  SmoothFunction(const SmoothFunction& other)
      : impl_(other.impl_ ? other.impl_->Clone() : nullptr) {}
  SmoothFunction& operator=(const SmoothFunction& other) {
    if (this != &other) impl_ = other.impl_ ? other.impl_->Clone() : nullptr;
    return *this;
  }
  SmoothFunction(SmoothFunction&&) noexcept = default;
  SmoothFunction& operator=(SmoothFunction&&) noexcept = default;

  /// True if no function was given (an effect's optional part, or zero dynamics).
  bool empty() const { return impl_ == nullptr; }
  const std::string& name() const;
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
  /// True for functions made by MakeSparseStateFunction (hand-written sparse dg/dx).
  bool has_sparse_state_jacobian() const;
  /// out = g and jac_x = dg/dx as a sparse matrix (only if has_sparse_state_jacobian()).
  void SparseStateJacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                           const ConstVectorRef& p, Vector* out, SparseMatrix* jac_x) const;

  /// Concept implemented by MakeSmoothFunction (public only for the factory template).
  class Concept {
   public:
    virtual ~Concept() = default;
    virtual std::unique_ptr<Concept> Clone() const = 0;
    virtual const std::string& name() const = 0;
    virtual int num_outputs() const = 0;
    virtual void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                          const ConstVectorRef& p, Vector* out) = 0;
    virtual void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                          const ConstVectorRef& p, Wrt wrt, Vector* out, Matrix* jac) = 0;
    virtual void WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                 const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                                 Matrix* hess) = 0;
    virtual bool has_sparse_state_jacobian() const { return false; }
    virtual void SparseStateJacobian(const ConstVectorRef& /*x*/, const ConstVectorRef& /*u*/,
                                     double /*t*/, const ConstVectorRef& /*p*/, Vector* /*out*/,
                                     SparseMatrix* /*jac_x*/) {}
  };
  explicit SmoothFunction(std::unique_ptr<Concept> impl) : impl_(std::move(impl)) {}

 private:
  std::unique_ptr<Concept> impl_;
};

namespace internal {

using Dual1 = Dual<double>;
using Dual2 = Dual<Dual<double>>;

// Implementation of SmoothFunction for a generic lambda F.
template <class F>
class AutoDiffFunction final : public SmoothFunction::Concept {
 public:
  AutoDiffFunction(std::string name, int num_outputs, F f)
      : name_(std::move(name)), num_outputs_(num_outputs), f_(std::move(f)) {}
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return std::make_unique<AutoDiffFunction>(name_, num_outputs_, f_);
  }
  const std::string& name() const override { return name_; }
  int num_outputs() const override { return num_outputs_; }

  void Evaluate(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Vector* out) override {
    out->setZero(num_outputs_);
    Call<double>(x.data(), static_cast<int>(x.size()), u.data(), static_cast<int>(u.size()), t,
                 p.data(), static_cast<int>(p.size()), out->data());
  }

  void Jacobian(const ConstVectorRef& x, const ConstVectorRef& u, double t, const ConstVectorRef& p,
                Wrt wrt, Vector* out, Matrix* jac) override {
    const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
              np = static_cast<int>(p.size());
    const int columns = wrt.Columns(nx, nu, np);
    jac->setZero(num_outputs_, columns);
    out->resize(num_outputs_);
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
      SeedInputs<Dual1>(x, u, t, p, wrt, seed);
      Call<Dual1>(space1_.x.data(), nx, space1_.u.data(), nu, space1_.t, space1_.p.data(), np,
                  space1_.out.data());
      for (int k = 0; k < num_outputs_; ++k) {
        const Dual1& value = space1_.out[k];
        if (first == 0) (*out)[k] = value.value();
        for (int i = 0; i < value.size(); ++i) (*jac)(k, first + i) = value.d(i);
      }
    }
  }

  void WeightedHessian(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                       const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                       Matrix* hess) override {
    const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
              np = static_cast<int>(p.size());
    const int columns = wrt.Columns(nx, nu, np);
    hess->setZero(columns, columns);
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
        SeedInputs<Dual2>(x, u, t, p, wrt, seed);
        Call<Dual2>(space2_.x.data(), nx, space2_.u.data(), nu, space2_.t, space2_.p.data(), np,
                    space2_.out.data());
        for (int k = 0; k < num_outputs_; ++k) {
          const Dual2& value = space2_.out[k];
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

 private:
  template <class T>
  void Call(const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np, T* out) {
    ArgVector<T> xv(x, nx, "x", &name_), uv(u, nu, "u", &name_), pv(p, np, "p", &name_);
    for (int k = 0; k < num_outputs_; ++k) out[k] = T(0.0);
    OutVector<T> ov(out, num_outputs_, &name_);
    f_(xv, uv, t, pv, ov);
  }

  // Fills the workspace of scalar type T; seed(value, column) returns the seeded scalar for a
  // selected input with Jacobian column `column`; unselected inputs become constants.
  template <class T, class Seed>
  void SeedInputs(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                  const ConstVectorRef& p, Wrt wrt, Seed&& seed) {
    auto& xs = Workspace<T>().x;
    auto& us = Workspace<T>().u;
    auto& ps = Workspace<T>().p;
    auto& os = Workspace<T>().out;
    xs.resize(x.size());
    us.resize(u.size());
    ps.resize(p.size());
    os.resize(num_outputs_);
    int column = 0;
    for (Eigen::Index i = 0; i < x.size(); ++i) xs[i] = wrt.x ? seed(x[i], column++) : T(x[i]);
    for (Eigen::Index i = 0; i < u.size(); ++i) us[i] = wrt.u ? seed(u[i], column++) : T(u[i]);
    Workspace<T>().t = wrt.t ? seed(t, column++) : T(t);
    for (Eigen::Index i = 0; i < p.size(); ++i) ps[i] = wrt.p ? seed(p[i], column++) : T(p[i]);
  }

  template <class T>
  struct Space {
    std::vector<T> x, u, p, out;
    T t;
  };
  template <class T>
  Space<T>& Workspace() {
    if constexpr (std::is_same_v<T, Dual1>) {
      return space1_;
    } else {
      return space2_;
    }
  }

  std::string name_;
  int num_outputs_;
  F f_;
  Space<Dual1> space1_;
  Space<Dual2> space2_;
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
