#include "moreau/core/smooth_function.hpp"

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
