// Switching surfaces lowered to Stewart's form or to the Heaviside step form
// (docs/lowering.md, sections "Stewart form" and "Heaviside step form").

#include <Eigen/Dense>
#include <cmath>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

// Sign of surface j in mode k (bit j of k set: c_j > 0).
double Sign(int mode, int surface) { return ((mode >> surface) & 1) ? 1.0 : -1.0; }

// Shared by both forms: the switching functions and the mode vector fields.
class SwitchingBlockBase : public LoweredBlock {
 public:
  SwitchingBlockBase(const Scene& scene, const SwitchingSurfaces& effect)
      : effect_(effect),
        num_states_(scene.num_states()),
        num_surfaces_(static_cast<int>(effect.surface_names.size())),
        num_modes_(1 << num_surfaces_) {
    // The surfaces and the mode fields stacked into one function: one forward-mode pass for
    // their Jacobians instead of 1 + 2^n_c (each pass seeds the inputs and sets up its
    // workspace, which on small scenes costs as much as the arithmetic). Functions with a
    // hand-written sparse Jacobian are not stackable; they keep separate passes.
    bool typed = effect.surfaces.typed() != nullptr;
    for (const SmoothFunction& mode : effect.modes) typed = typed && mode.typed() != nullptr;
    if (typed) {
      std::vector<SmoothFunction> parts{effect.surfaces};
      parts.insert(parts.end(), effect.modes.begin(), effect.modes.end());
      stacked_ = MakeStackedFunction(effect.name + ".surfaces_and_modes", parts);
      has_stacked_ = true;
    }
  }

  // The mode fields are physical-time dynamics (time-freezing scales them).
  bool ScaledByClockRate() const override { return true; }

 protected:
  // Evaluates the surfaces c (with derivatives per `derivatives`, columns x, [u], t, [p]).
  void EvaluateSurfaces(const BlockContext& context, const ConstVectorRef& y,
                        Derivatives derivatives) {
    x_ = y.head(num_states_);
    c_jacobian_.Jacobian(context, effect_.surfaces, y, derivatives, &c_);
  }
  // Evaluates mode k's vector field into f_[k] (and its Jacobian into f_jacobian_[k]).
  void EvaluateModes(const BlockContext& context, const ConstVectorRef& y,
                     Derivatives derivatives) {
    f_.resize(static_cast<std::size_t>(num_modes_));
    f_jacobian_.resize(static_cast<std::size_t>(num_modes_));
    for (int k = 0; k < num_modes_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      f_jacobian_[i].Jacobian(context, effect_.modes[i], y, derivatives, &f_[i]);
    }
  }
  // EvaluateSurfaces and EvaluateModes together; with dense derivatives or values alone by one pass
  // over the stacked function (the same values and derivatives, entry for entry: its parts'
  // own code in turn). Read the derivatives with AddSurfaceRow and AddModeRows.
  void EvaluateSurfacesAndModes(const BlockContext& context, const ConstVectorRef& y,
                                Derivatives derivatives) {
    use_stacked_ = has_stacked_ && (!context.sparse || derivatives == Derivatives::kNone);
    if (!use_stacked_) {
      EvaluateSurfaces(context, y, derivatives);
      EvaluateModes(context, y, derivatives);
      return;
    }
    x_ = y.head(num_states_);
    stacked_jacobian_.Jacobian(context, stacked_, y, derivatives, &stacked_values_);
    c_ = stacked_values_.head(num_surfaces_);
    f_.resize(static_cast<std::size_t>(num_modes_));
    int row = num_surfaces_;
    for (int k = 0; k < num_modes_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      const int outputs = effect_.modes[i].num_outputs();
      f_[i] = stacked_values_.segment(row, outputs);
      row += outputs;
    }
  }
  // Surface j's derivative row, times weight, added to row `row` (after the last evaluation).
  void AddSurfaceRow(int j, double weight, int row, DerivativeMatrix* dy, DerivativeMatrix* du,
                     DerivativeMatrix* dp) const {
    if (use_stacked_) {
      stacked_jacobian_.AddRow(j, weight, row, dy, du, dp);
    } else {
      c_jacobian_.AddRow(j, weight, row, dy, du, dp);
    }
  }
  // Mode k's derivative rows, times weight, added from row row0.
  void AddModeRows(int k, double weight, int row0, DerivativeMatrix* dy, DerivativeMatrix* du,
                   DerivativeMatrix* dp) const {
    const auto i = static_cast<std::size_t>(k);
    const int outputs = effect_.modes[i].num_outputs();
    if (!use_stacked_) {
      f_jacobian_[i].AddRows(0, outputs, weight, row0, dy, du, dp);
      return;
    }
    int first = num_surfaces_;
    for (int m = 0; m < k; ++m) first += effect_.modes[static_cast<std::size_t>(m)].num_outputs();
    stacked_jacobian_.AddRows(first, outputs, weight, row0, dy, du, dp);
  }

  // Enclosures of the surfaces c over a box into c_bounds_ (false if there are none).
  bool SurfaceBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                     const ConstVectorRef& y_upper) {
    if (!FunctionBounds(context, effect_.surfaces, y_lower, y_upper, &c_lower_, &c_upper_)) {
      return false;
    }
    c_bounds_.resize(static_cast<std::size_t>(num_surfaces_));
    for (int j = 0; j < num_surfaces_; ++j) {
      c_bounds_[static_cast<std::size_t>(j)] = Interval(c_lower_[j], c_upper_[j]);
    }
    return true;
  }

  // True if some switching function vanishes to round-off at the last evaluated point.
  bool OnSurface() const {
    for (Eigen::Index j = 0; j < c_.size(); ++j) {
      if (std::fabs(c_[j]) <= kOnSurfaceTolerance * (1.0 + x_.lpNorm<Eigen::Infinity>())) {
        return true;
      }
    }
    return false;
  }
  // |c| below this (relative to the state's size) counts as lying on the surface: round-off
  // of a state that slides along it.
  static constexpr double kOnSurfaceTolerance = 1e-10;

  std::string ModeName(int k) const { return effect_.mode_names[static_cast<std::size_t>(k)]; }

  SwitchingSurfaces effect_;
  int num_states_;
  int num_surfaces_;
  int num_modes_;
  Vector x_, c_;
  Vector c_lower_, c_upper_;        // SurfaceBounds' enclosures
  std::vector<Interval> c_bounds_;  // the same as intervals
  ArgumentMatrix c_jacobian_, directions_;
  std::vector<Vector> f_;
  std::vector<ArgumentMatrix> f_jacobian_;
  SmoothFunction stacked_;  // (c, f_0, ..., f_{m-1}) if every part is typed
  bool has_stacked_ = false;
  bool use_stacked_ = false;  // the last EvaluateSurfacesAndModes used stacked_
  ArgumentMatrix stacked_jacobian_;
  Vector stacked_values_;
};

// Stewart: regions R_k = {g_k(x) = min_i g_i(x)} with g = -S c (S_kj = sign of surface j in
// mode k, so g_k is smallest exactly where the signs of c match mode k).
//   x' += sum_k theta_k f_k,   0 = g - lambda - mu e,   0 = e^T theta - 1,
//   0 <= theta_k ⟂ lambda_k >= 0.
// z = (theta (m), lambda (m), mu); lambda_k = g_k - min g is the continuous side.
class StewartBlock final : public SwitchingBlockBase {
 public:
  using SwitchingBlockBase::SwitchingBlockBase;
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<StewartBlock>(*this);
  }
  int num_algebraic() const override { return 2 * num_modes_ + 1; }
  int num_equations() const override { return num_modes_ + 1; }
  int num_pairs() const override { return num_modes_; }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (int k = 0; k < num_modes_; ++k) names.push_back(effect_.name + ".theta_" + ModeName(k));
    for (int k = 0; k < num_modes_; ++k) names.push_back(effect_.name + ".lambda_" + ModeName(k));
    names.push_back(effect_.name + ".mu");
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (int k = 0; k < num_modes_; ++k) {
      pairs.push_back({effect_.name, effect_.name + "." + ModeName(k), ContinuousSide::kB, 0});
    }
    return pairs;
  }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    const int m = num_modes_;
    const int z0 = layout.z_offset;  // theta at z0, lambda at z0 + m, mu at z0 + 2m
    const int g0 = layout.g_offset;
    const int k0 = layout.pair_offset;
    if (context.switching_mode >= 0) {
      // EvaluateField of one mode (theta = e_mode): x' = f_mode, added with its Jacobian rows
      // of weight 1 exactly as a system lowered from the dynamics f_mode adds them (FESD's
      // smooth elements; G, A, B are not read).
      const auto i = static_cast<std::size_t>(context.switching_mode);
      mode_field_.Jacobian(context, effect_.modes[i], y, derivatives, &mode_values_);
      out->F.head(nx) += mode_values_;
      if (derivatives != Derivatives::kNone) {
        mode_field_.AddRows(0, nx, 1.0, 0, &out->F_y, &out->F_u, &out->F_p);
      }
      return;
    }
    EvaluateSurfacesAndModes(context, y, derivatives);
    const auto theta = z.segment(z0, m);
    const auto lambda = z.segment(z0 + m, m);
    const double mu = z[z0 + 2 * m];
    for (int k = 0; k < m; ++k) {
      const auto i = static_cast<std::size_t>(k);
      // (Stewart) x' += theta_k f_k.
      out->F.head(nx) += theta[k] * f_[i];
      // g_k - lambda_k - mu = 0 with g_k = -sum_j S_kj c_j.
      double g = 0.0;
      for (int j = 0; j < num_surfaces_; ++j) g -= Sign(k, j) * c_[j];
      out->G[g0 + k] = g - lambda[k] - mu;
      // pair k: a = theta_k, b = lambda_k.
      out->A[k0 + k] = theta[k];
      out->B[k0 + k] = lambda[k];
    }
    out->G[g0 + m] = theta.sum() - 1.0;  // convex combination
    if (derivatives == Derivatives::kNone) return;

    for (int k = 0; k < m; ++k) {
      const auto i = static_cast<std::size_t>(k);
      AddModeRows(k, theta[k], 0, &out->F_y, &out->F_u, &out->F_p);
      out->F_z.AddBlock(0, z0 + k, f_[i]);
      for (int j = 0; j < num_surfaces_; ++j) {
        AddSurfaceRow(j, -Sign(k, j), g0 + k, &out->G_y, &out->G_u, &out->G_p);
      }
      out->G_z.Add(g0 + k, z0 + m + k, -1.0);
      out->G_z.Add(g0 + k, z0 + 2 * m, -1.0);
      out->G_z.Add(g0 + m, z0 + k, 1.0);
      out->A_z.Add(k0 + k, z0 + k, 1.0);
      out->B_z.Add(k0 + k, z0 + m + k, 1.0);
    }
  }

  // theta is a jump variable; lambda and mu are continuous (lambda = g - min g).
  std::vector<bool> ContinuousAlgebraic() const override {
    std::vector<bool> continuous(static_cast<std::size_t>(2 * num_modes_ + 1), true);
    for (int k = 0; k < num_modes_; ++k) continuous[static_cast<std::size_t>(k)] = false;
    return continuous;
  }
  // g - lambda - mu e = 0 is differentiated; e^T theta = 1 holds on values.
  std::vector<bool> DifferentiatedEquations() const override {
    std::vector<bool> rows(static_cast<std::size_t>(num_modes_ + 1), true);
    rows.back() = false;
    return rows;
  }

  // Row k: d/d(y, u, p) [grad_y g_k . d] = -sum_j S_kj Hess c_j d.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    directions_.HessianDirections(context, effect_.surfaces, y, direction, derivatives);
    for (int j = 0; j < num_surfaces_; ++j) {
      for (int k = 0; k < num_modes_; ++k) {
        directions_.AddRow(j, -Sign(k, j), layout.g_offset + k, &out->equation_y, &out->equation_u,
                           &out->equation_p);
      }
    }
  }

  // Active mode (lambda = 0 kept): theta (velocity level); inactive mode j:
  // lambda_j = g_j - g_i, i the first active mode.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    int active = -1;
    for (int k = 0; k < num_modes_ && active < 0; ++k) {
      if (!a_zero[static_cast<std::size_t>(k0 + k)]) active = k;
    }
    MOREAU_ASSERT(active >= 0, "Stewart statuses without an active mode");
    EvaluateSurfaces(context, y, derivatives);
    for (int k = 0; k < num_modes_; ++k) {
      if (!a_zero[static_cast<std::size_t>(k0 + k)]) {
        out->values[k0 + k] = v[z0 + k];
        if (derivatives != Derivatives::kNone) out->d_v.Add(k0 + k, z0 + k, 1.0);
        continue;
      }
      double value = 0.0;
      for (int j = 0; j < num_surfaces_; ++j) value -= (Sign(k, j) - Sign(active, j)) * c_[j];
      out->values[k0 + k] = value;
      if (derivatives == Derivatives::kNone) continue;
      for (int j = 0; j < num_surfaces_; ++j) {
        const double weight = -(Sign(k, j) - Sign(active, j));
        if (weight != 0.0) c_jacobian_.AddRow(j, weight, k0 + k, &out->d_y, &out->d_u, &out->d_p);
      }
    }
  }

  // Inactive mode k: lambda_k = g_k - g_active = -(S_k - S_active) c over the box.
  void IndicatorBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                       const ConstVectorRef& y_upper, const std::vector<bool>& a_zero,
                       VectorRef lower, VectorRef upper) override {
    const int k0 = layout.pair_offset;
    int active = -1;
    for (int k = 0; k < num_modes_ && active < 0; ++k) {
      if (!a_zero[static_cast<std::size_t>(k0 + k)]) active = k;
    }
    if (active < 0 || !SurfaceBounds(context, y_lower, y_upper)) return;
    for (int k = 0; k < num_modes_; ++k) {
      if (!a_zero[static_cast<std::size_t>(k0 + k)]) continue;
      Interval value(0.0);
      for (int j = 0; j < num_surfaces_; ++j) {
        const double weight = -(Sign(k, j) - Sign(active, j));
        if (weight != 0.0) value += weight * c_bounds_[static_cast<std::size_t>(j)];
      }
      lower[k0 + k] = value.lower();
      upper[k0 + k] = value.upper();
    }
  }

  // theta = e_k for the region containing y, lambda = g - min g, mu = min g. If y lies on
  // a switching surface (|c_j| at round-off level) the region does not decide: keep
  // `previous` (e.g. a sliding mode's theta) when given.
  void InitialGuess(const BlockContext& context, const ConstVectorRef& y, const Vector* previous,
                    VectorRef z) override {
    EvaluateSurfaces(context, y, Derivatives::kNone);
    const int m = num_modes_;
    const int z0 = layout.z_offset;
    if (previous != nullptr && OnSurface()) {
      z.segment(z0, 2 * m + 1) = previous->segment(z0, 2 * m + 1);
      return;
    }
    Vector& g = guess_g_;
    g.resize(m);
    for (int k = 0; k < m; ++k) {
      g[k] = 0.0;
      for (int j = 0; j < num_surfaces_; ++j) g[k] -= Sign(k, j) * c_[j];
    }
    Eigen::Index best = 0;
    const double g_min = g.minCoeff(&best);
    z.segment(z0, m).setZero();
    z[z0 + best] = 1.0;
    z.segment(z0 + m, m) = g.array() - g_min;
    z[z0 + 2 * m] = g_min;
  }

  // x' += sum theta_k f_k(x), g(x) - lambda - mu e, e^T theta - 1, (theta, lambda).
  bool AffineInAlgebraic() const override { return true; }

  // Some theta must be free: they sum to one.
  bool AdmitsRoles(const std::vector<PairRole>& roles) const override {
    for (PairRole role : roles) {
      if (role != PairRole::kAZero) return true;
    }
    return false;
  }

  // Pair k has b = lambda_k = 0 (a_zero false) exactly when mode k is active.
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<int> active_before, active_after;
    for (int k = 0; k < num_modes_; ++k) {
      if (!before[static_cast<std::size_t>(k)]) active_before.push_back(k);
      if (!after[static_cast<std::size_t>(k)]) active_after.push_back(k);
    }
    if (active_before == active_after) return {};
    auto names = [this](const std::vector<int>& modes) {
      std::string s;
      for (int k : modes) s += (s.empty() ? "" : "+") + ModeName(k);
      return s.empty() ? std::string("none") : s;
    };
    EventKind kind = EventKind::kModeSwitch;
    if (active_after.size() > active_before.size()) kind = EventKind::kSlideStart;
    if (active_after.size() < active_before.size()) kind = EventKind::kSlideEnd;
    return {{t, kind, effect_.name, names(active_before) + " -> " + names(active_after)}};
  }

 private:
  Vector guess_g_;  // InitialGuess's g, kept (it is called for every stage of every element)
  ArgumentMatrix mode_field_;  // one mode's field (BlockContext::switching_mode)
  Vector mode_values_;
};

// Heaviside step form: one alpha_j in [0, 1] per surface,
//   x' += sum_k w_k(alpha) f_k,  w_k = prod_j (alpha_j if bit j of k else 1 - alpha_j),
//   0 = c_j - lambda_p_j + lambda_n_j,
//   0 <= alpha_j ⟂ lambda_n_j >= 0,   0 <= 1 - alpha_j ⟂ lambda_p_j >= 0.
// z = (alpha (n_c), lambda_n (n_c), lambda_p (n_c)); lambda_n, lambda_p are continuous.
class HeavisideBlock final : public SwitchingBlockBase {
 public:
  using SwitchingBlockBase::SwitchingBlockBase;
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<HeavisideBlock>(*this);
  }
  int num_algebraic() const override { return 3 * num_surfaces_; }
  int num_equations() const override { return num_surfaces_; }
  int num_pairs() const override { return 2 * num_surfaces_; }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (const char* prefix : {".alpha_", ".lambda_n_", ".lambda_p_"}) {
      for (const std::string& s : effect_.surface_names) names.push_back(effect_.name + prefix + s);
    }
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (const std::string& s : effect_.surface_names) {
      pairs.push_back({effect_.name, effect_.name + "." + s + ".negative", ContinuousSide::kB, 0});
      pairs.push_back({effect_.name, effect_.name + "." + s + ".positive", ContinuousSide::kB, 0});
    }
    return pairs;
  }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    const int nc = num_surfaces_;
    const int z0 = layout.z_offset;  // alpha at z0, lambda_n at z0 + nc, lambda_p at z0 + 2nc
    const int g0 = layout.g_offset;
    const int k0 = layout.pair_offset;
    EvaluateSurfaces(context, y, derivatives);
    EvaluateModes(context, y, derivatives);
    const auto alpha = z.segment(z0, nc);
    const auto lambda_n = z.segment(z0 + nc, nc);
    const auto lambda_p = z.segment(z0 + 2 * nc, nc);
    for (int k = 0; k < num_modes_; ++k) {
      // (Heaviside) x' += w_k(alpha) f_k.
      out->F.head(nx) += Weight(k, alpha, -1) * f_[static_cast<std::size_t>(k)];
    }
    for (int j = 0; j < nc; ++j) {
      out->G[g0 + j] = c_[j] - lambda_p[j] + lambda_n[j];
      out->A[k0 + 2 * j] = alpha[j];  // alpha_j ⟂ lambda_n_j
      out->B[k0 + 2 * j] = lambda_n[j];
      out->A[k0 + 2 * j + 1] = 1.0 - alpha[j];  // 1 - alpha_j ⟂ lambda_p_j
      out->B[k0 + 2 * j + 1] = lambda_p[j];
    }
    if (derivatives == Derivatives::kNone) return;

    for (int k = 0; k < num_modes_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      f_jacobian_[i].AddRows(0, nx, Weight(k, alpha, -1), 0, &out->F_y, &out->F_u, &out->F_p);
      for (int j = 0; j < nc; ++j) {
        // d w_k / d alpha_j = sign * prod_{l != j} (...)
        out->F_z.AddBlock(0, z0 + j, f_[i], Sign(k, j) * Weight(k, alpha, j));
      }
    }
    for (int j = 0; j < nc; ++j) {
      c_jacobian_.AddRow(j, 1.0, g0 + j, &out->G_y, &out->G_u, &out->G_p);
      out->G_z.Add(g0 + j, z0 + 2 * nc + j, -1.0);
      out->G_z.Add(g0 + j, z0 + nc + j, 1.0);
      out->A_z.Add(k0 + 2 * j, z0 + j, 1.0);
      out->B_z.Add(k0 + 2 * j, z0 + nc + j, 1.0);
      out->A_z.Add(k0 + 2 * j + 1, z0 + j, -1.0);
      out->B_z.Add(k0 + 2 * j + 1, z0 + 2 * nc + j, 1.0);
    }
  }

  // The weights w_k(alpha) are multi-affine: affine in alpha for one surface only.
  bool AffineInAlgebraic() const override { return num_surfaces_ == 1; }

  // alpha is a jump variable; lambda_n and lambda_p are continuous.
  std::vector<bool> ContinuousAlgebraic() const override {
    std::vector<bool> continuous(static_cast<std::size_t>(3 * num_surfaces_), true);
    for (int j = 0; j < num_surfaces_; ++j) continuous[static_cast<std::size_t>(j)] = false;
    return continuous;
  }
  std::vector<bool> DifferentiatedEquations() const override {
    return std::vector<bool>(static_cast<std::size_t>(num_surfaces_), true);
  }

  // Row j: d/d(y, u, p) [grad_y c_j . d] = Hess c_j d.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    directions_.HessianDirections(context, effect_.surfaces, y, direction, derivatives);
    directions_.AddRows(0, num_surfaces_, 1.0, layout.g_offset, &out->equation_y, &out->equation_u,
                        &out->equation_p);
  }

  // Pair 2j (alpha ⟂ lambda_n): alpha = 0 kept -> lambda_n = -c_j; else alpha. Pair 2j+1
  // (1 - alpha ⟂ lambda_p): 1 - alpha = 0 kept -> lambda_p = c_j; else 1 - alpha.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    EvaluateSurfaces(context, y, derivatives);
    for (int j = 0; j < num_surfaces_; ++j) {
      for (int side = 0; side < 2; ++side) {
        const int pair = k0 + 2 * j + side;
        const double sign = side == 0 ? -1.0 : 1.0;  // lambda_n = -c, lambda_p = c
        if (a_zero[static_cast<std::size_t>(pair)]) {
          out->values[pair] = sign * c_[j];
          if (derivatives != Derivatives::kNone) {
            c_jacobian_.AddRow(j, sign, pair, &out->d_y, &out->d_u, &out->d_p);
          }
        } else {
          out->values[pair] = side == 0 ? v[z0 + j] : 1.0 - v[z0 + j];
          if (derivatives != Derivatives::kNone) out->d_v.Add(pair, z0 + j, side == 0 ? 1.0 : -1.0);
        }
      }
    }
  }

  // Pairs 2j (alpha_j, lambda_n) and 2j + 1 (1 - alpha_j, lambda_p) whose alpha side is kept
  // at zero: their free sides lambda_n = -c_j and lambda_p = c_j over the box.
  void IndicatorBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                       const ConstVectorRef& y_upper, const std::vector<bool>& a_zero,
                       VectorRef lower, VectorRef upper) override {
    if (!SurfaceBounds(context, y_lower, y_upper)) return;
    const int k0 = layout.pair_offset;
    for (int j = 0; j < num_surfaces_; ++j) {
      for (int side = 0; side < 2; ++side) {
        const int pair = k0 + 2 * j + side;
        if (!a_zero[static_cast<std::size_t>(pair)]) continue;
        const Interval value = side == 0 ? -c_bounds_[static_cast<std::size_t>(j)]
                                         : c_bounds_[static_cast<std::size_t>(j)];
        lower[pair] = value.lower();
        upper[pair] = value.upper();
      }
    }
  }

  // alpha_j = 1 where c_j > 0, 0 where c_j < 0, 1/2 on the surface; lambda_p/n = c_j^+/-.
  // On a surface (|c_j| at round-off level) `previous` is kept when given.
  void InitialGuess(const BlockContext& context, const ConstVectorRef& y, const Vector* previous,
                    VectorRef z) override {
    EvaluateSurfaces(context, y, Derivatives::kNone);
    const int nc = num_surfaces_;
    const int z0 = layout.z_offset;
    if (previous != nullptr && OnSurface()) {
      z.segment(z0, 3 * nc) = previous->segment(z0, 3 * nc);
      return;
    }
    for (int j = 0; j < nc; ++j) {
      z[z0 + j] = c_[j] > 0.0 ? 1.0 : (c_[j] < 0.0 ? 0.0 : 0.5);
      z[z0 + nc + j] = std::max(-c_[j], 0.0);
      z[z0 + 2 * nc + j] = std::max(c_[j], 0.0);
    }
  }

  // alpha_j = 0 and 1 - alpha_j = 0 cannot both be kept.
  bool AdmitsRoles(const std::vector<PairRole>& roles) const override {
    for (int j = 0; j < num_surfaces_; ++j) {
      if (roles[static_cast<std::size_t>(2 * j)] == PairRole::kAZero &&
          roles[static_cast<std::size_t>(2 * j + 1)] == PairRole::kAZero) {
        return false;
      }
    }
    return true;
  }

  // Surface j: pair 2j has a_zero when alpha_j = 0 (negative side), pair 2j+1 when
  // alpha_j = 1 (positive side); both b-zero means sliding.
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<Event> events;
    auto state = [](const std::vector<bool>& s, int j) {
      const bool negative = s[static_cast<std::size_t>(2 * j)];
      const bool positive = s[static_cast<std::size_t>(2 * j + 1)];
      if (negative && !positive) return std::string("negative");
      if (positive && !negative) return std::string("positive");
      return std::string("sliding");
    };
    for (int j = 0; j < num_surfaces_; ++j) {
      const std::string from = state(before, j), to = state(after, j);
      if (from == to) continue;
      EventKind kind = EventKind::kModeSwitch;
      if (to == "sliding") kind = EventKind::kSlideStart;
      if (from == "sliding") kind = EventKind::kSlideEnd;
      events.push_back({t, kind,
                        effect_.name + "." + effect_.surface_names[static_cast<std::size_t>(j)],
                        from + " -> " + to});
    }
    return events;
  }

 private:
  // w_k(alpha) with factor `skip` left out (skip = -1: none).
  double Weight(int mode, const Eigen::Ref<const Vector>& alpha, int skip) const {
    double w = 1.0;
    for (int j = 0; j < num_surfaces_; ++j) {
      if (j == skip) continue;
      w *= ((mode >> j) & 1) ? alpha[j] : 1.0 - alpha[j];
    }
    return w;
  }
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerStewart(const Scene& scene, const SwitchingSurfaces& effect) {
  return std::make_unique<StewartBlock>(scene, effect);
}

std::unique_ptr<LoweredBlock> LowerHeaviside(const Scene& scene, const SwitchingSurfaces& effect) {
  return std::make_unique<HeavisideBlock>(scene, effect);
}

}  // namespace moreau::internal
