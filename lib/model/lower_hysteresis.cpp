// Hysteresis relays lowered by time-freezing (docs/lowering.md, "Hysteresis relays";
// ../shared/papers/hysteresis-time-freezing.md). Relay i gets a memory state w_i in y and a
// Stewart subsystem over the Voronoi regions of the (psi_i, w_i) plane:
//
//   R1 (z = (1/4, -1/4)): DAE-forming field of mode A     w' = +a
//   R2 (z = (1/4,  1/4)): auxiliary field, jump B -> A     w' = -a, x' = 0, clock' = 0
//   R3 (z = (3/4,  3/4)): auxiliary field, jump A -> B     w' = +a, x' = 0, clock' = 0
//   R4 (z = (3/4,  5/4)): DAE-forming field of mode B     w' = -a
//
// The relay evolves in physical time on the region boundaries w = 0 (R1/R2, theta = 1/2
// each) and w = 1 (R3/R4). With r_i = 2 (theta_i1 + theta_i4) (1 on those boundaries, 0 while
// the relay is in R2 or R3 alone) and P = prod_i r_i, Q_i = prod_{j != i} r_j:
//
//   x'     = P (f + switching modes) + sum_i Q_i (2 theta_i1 f_A,i + 2 theta_i4 f_B,i) + E E^T grad
//   c lambda w_i'   = a_i (theta_i1 - theta_i2 + theta_i3 - theta_i4) clock' = P 0 = g_ik -
//   lambda_ik - mu_i,  g_ik = |z_k|^2 - 2 z_k . (psi_i, w_i)     (k = 1..4) 0 = sum_k theta_ik - 1,
//   0 <= theta_ik ⟂ lambda_ik >= 0.
//
// The scaling by P lives in LoweredSystem::Evaluate (ClockRate below); this block adds the
// relay fields, the memory dynamics and the Stewart equations.

#include <Eigen/Dense>
#include <cmath>
#include <limits>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

constexpr int kRegions = 4;
enum Region { kModeA = 0, kToA = 1, kToB = 2, kModeB = 3 };
// Voronoi points (psi, w) of R1..R4 (the paper's choice; region boundaries w = 0 for
// psi < 1 and w = 1 for psi > 0 carry the original system, the diagonal psi + w = 1 separates
// the two auxiliary regions).
constexpr double kPointPsi[kRegions] = {0.25, 0.25, 0.75, 0.75};
constexpr double kPointW[kRegions] = {-0.25, 0.25, 0.75, 1.25};
constexpr const char* kRegionNames[kRegions] = {"mode_A", "to_A", "to_B", "mode_B"};
// Direction of w' in each region (speed a).
constexpr double kMemoryDirection[kRegions] = {1.0, -1.0, 1.0, -1.0};
// Unknowns, equations and pairs per relay.
constexpr int kUnknownsPerRelay = 2 * kRegions + 1;
constexpr int kEquationsPerRelay = kRegions + 1;

double PointNormSquared(int k) { return kPointPsi[k] * kPointPsi[k] + kPointW[k] * kPointW[k]; }

// What both relay lowerings share: the memories, the normalized inputs psi and the mode fields.
class RelayBlockBase : public LoweredBlock {
 public:
  RelayBlockBase(const Scene& scene, const std::vector<HysteresisRelay>& relays)
      : relays_(relays),
        num_states_(scene.num_states()),
        num_relays_(static_cast<int>(relays.size())) {
    for (const HysteresisRelay& relay : relays_) {
      RequireArgument(!relay.input.has_sparse_state_jacobian(), "hysteresis relay '", relay.name,
                      "': the input function needs second derivatives; write it as a generic "
                      "lambda (MakeSmoothFunction)");
    }
  }
  int num_internal_states() const override { return num_relays_; }
  std::vector<std::string> InternalStateNames() const override {
    std::vector<std::string> names;
    for (const HysteresisRelay& relay : relays_) names.push_back(relay.name + ".w");
    return names;
  }
  void InitialInternalStates(VectorRef y) const override {
    for (int i = 0; i < num_relays_; ++i) {
      y[MemoryIndex(i)] = relays_[static_cast<std::size_t>(i)].initial_memory;
    }
  }

 protected:
  // Normalized input psi_i = (input - L)/(U - L) and its derivatives.
  struct Psi {
    double value = 0.0;
    double width = 1.0;  // U - L
    Eigen::RowVectorXd d_y, d_u, d_p;
  };

  int MemoryIndex(int i) const { return layout.y_offset + i; }

  void EvaluateInputs(const BlockContext& context, const ConstVectorRef& y,
                      Derivatives derivatives) {
    const int nx = num_states_;
    const int ny = context.clock_index + 1;
    const Vector& u = *context.inputs;
    const Vector& params = *context.parameters;
    const int nu = static_cast<int>(u.size());
    const int np = static_cast<int>(params.size());
    const bool all = derivatives == Derivatives::kAll;
    x_ = y.head(nx);
    const double t = y[context.clock_index];
    psi_.resize(static_cast<std::size_t>(num_relays_));
    for (int i = 0; i < num_relays_; ++i) {
      const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
      Psi& p = psi_[static_cast<std::size_t>(i)];
      const double lower = params[relay.lower_threshold];
      const double upper = params[relay.upper_threshold];
      p.width = upper - lower;
      if (derivatives == Derivatives::kNone) {
        relay.input.Evaluate(x_, u, t, params, &input_);
        p.value = (input_[0] - lower) / p.width;
        continue;
      }
      relay.input.Jacobian(x_, u, t, params, all ? Wrt::All() : Wrt::XT(), &input_,
                           &input_jacobian_);
      p.value = (input_[0] - lower) / p.width;
      const int t_col = all ? nx + nu : nx;
      p.d_y.setZero(ny);
      p.d_y.head(nx) = input_jacobian_.block(0, 0, 1, nx) / p.width;
      p.d_y[context.clock_index] = input_jacobian_(0, t_col) / p.width;
      if (!all) continue;
      p.d_u = input_jacobian_.block(0, nx, 1, nu) / p.width;
      p.d_p = input_jacobian_.block(0, t_col + 1, 1, np) / p.width;
      // psi = (v - L)/(U - L): dpsi/dL = (v - U)/(U - L)^2, dpsi/dU = -(v - L)/(U - L)^2.
      p.d_p[relay.lower_threshold] += (input_[0] - upper) / (p.width * p.width);
      p.d_p[relay.upper_threshold] -= (input_[0] - lower) / (p.width * p.width);
    }
  }

  // Enclosures of psi_i over a box into psi_bounds_; false if an input has none.
  bool PsiBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                 const ConstVectorRef& y_upper) {
    const Vector& params = *context.parameters;
    psi_bounds_.resize(static_cast<std::size_t>(num_relays_));
    for (int i = 0; i < num_relays_; ++i) {
      const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
      if (!FunctionBounds(context, relay.input, y_lower, y_upper, &input_lower_, &input_upper_)) {
        return false;
      }
      const double lower = params[relay.lower_threshold];
      const double upper = params[relay.upper_threshold];
      psi_bounds_[static_cast<std::size_t>(i)] =
          (Interval(input_lower_[0], input_upper_[0]) - lower) / Interval(upper - lower);
    }
    return true;
  }

  // One mode field's values (no derivatives).
  static void EvaluateMode(const BlockContext& context, const ConstVectorRef& y,
                           const SmoothFunction& mode, ArgumentMatrix* jacobian, Vector* values) {
    jacobian->Jacobian(context, mode, y, Derivatives::kNone, values);
  }

  // f_A,i and f_B,i (with Jacobians, columns x, [u], t, [p]).
  void EvaluateModes(const BlockContext& context, const ConstVectorRef& y, int i,
                     Derivatives derivatives) {
    const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
    mode_a_jacobian_.Jacobian(context, relay.mode_a, y, derivatives, &mode_a_);
    mode_b_jacobian_.Jacobian(context, relay.mode_b, y, derivatives, &mode_b_);
  }

  // Adds weight * d(mode field)/d(y, u, p) into the x rows of F_y (x and clock columns),
  // F_u and F_p.
  void AddModeJacobian(const ArgumentMatrix& jacobian, double weight, PointEvaluation* out) const {
    jacobian.AddRows(0, num_states_, weight, 0, &out->F_y, &out->F_u, &out->F_p);
  }

  std::vector<HysteresisRelay> relays_;
  int num_states_;
  int num_relays_;
  std::vector<Psi> psi_;
  std::vector<Interval> psi_bounds_;  // PsiBounds' enclosures
  Vector input_lower_, input_upper_;
  Vector x_, input_, mode_a_, mode_b_;
  Matrix input_jacobian_;
  ArgumentMatrix mode_a_jacobian_, mode_b_jacobian_, directions_;
};

class HysteresisBlock final : public RelayBlockBase {
 public:
  using RelayBlockBase::RelayBlockBase;
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<HysteresisBlock>(*this);
  }
  int num_algebraic() const override { return kUnknownsPerRelay * num_relays_; }
  int num_equations() const override { return kEquationsPerRelay * num_relays_; }
  int num_pairs() const override { return kRegions * num_relays_; }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (const HysteresisRelay& relay : relays_) {
      for (int k = 0; k < kRegions; ++k) names.push_back(relay.name + ".theta_" + kRegionNames[k]);
      for (int k = 0; k < kRegions; ++k) names.push_back(relay.name + ".lambda_" + kRegionNames[k]);
      names.push_back(relay.name + ".mu");
    }
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (const HysteresisRelay& relay : relays_) {
      for (int k = 0; k < kRegions; ++k) {
        pairs.push_back({relay.name, relay.name + "." + kRegionNames[k], ContinuousSide::kB, 0});
      }
    }
    return pairs;
  }

  bool HasClockRate() const override { return true; }

  // One relay: F (x' = P f + 2 theta_1 f_A + 2 theta_4 f_B, Q_1 = 1; w' and clock' = P), G,
  // A, B are affine in z, with P = 2 (theta_1 + theta_4) affine too; the roles are not read.
  // With several relays P and Q_i are products of the thetas.
  bool AffineInAlgebraic() const override { return num_relays_ == 1; }

  // P = prod_i r_i, dP/dtheta_j1 = dP/dtheta_j4 = 2 prod_{l != j} r_l.
  double ClockRate(const ConstVectorRef& z, Eigen::RowVectorXd* d_rate_dz) const override {
    Rates(z);
    double rate = 1.0;
    for (int i = 0; i < num_relays_; ++i) rate *= rates_[i];
    if (d_rate_dz != nullptr) {
      d_rate_dz->setZero(z.size());
      for (int j = 0; j < num_relays_; ++j) {
        const double others = ProductExcept(j, -1);
        (*d_rate_dz)[Theta(j, kModeA)] = 2.0 * others;
        (*d_rate_dz)[Theta(j, kModeB)] = 2.0 * others;
      }
    }
    return rate;
  }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    // F alone (LoweredSystem::EvaluateField): the inputs psi enter only G, which is skipped
    // with A, B and their derivatives.
    const bool field_only = context.field_only;
    if (!field_only) EvaluateInputs(context, y, derivatives);
    Rates(z);
    for (int i = 0; i < num_relays_; ++i) {
      const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
      const double w = y[MemoryIndex(i)];
      const double psi = field_only ? 0.0 : psi_[static_cast<std::size_t>(i)].value;
      double theta_sum = 0.0, memory_rate = 0.0;
      for (int k = 0; k < kRegions; ++k) {
        const double theta = z[Theta(i, k)];
        theta_sum += theta;
        memory_rate += kMemoryDirection[k] * theta;
        if (field_only) continue;
        // g_ik - lambda_ik - mu_i = 0 (Voronoi indicator of region k).
        out->G[Row(i, k)] = Indicator(k, psi, w) - z[Lambda(i, k)] - z[Mu(i)];
        // pair (theta_ik, lambda_ik).
        out->A[Pair(i, k)] = theta;
        out->B[Pair(i, k)] = z[Lambda(i, k)];
      }
      if (!field_only) out->G[Row(i, kRegions)] = theta_sum - 1.0;  // convex combination
      // w_i' = a_i (theta_1 - theta_2 + theta_3 - theta_4).
      out->F[MemoryIndex(i)] += relay.auxiliary_gain * memory_rate;
      // x' += Q_i (2 theta_i1 f_A + 2 theta_i4 f_B).
      const double q = ProductExcept(i, -1);
      const double weight_a = 2.0 * z[Theta(i, kModeA)], weight_b = 2.0 * z[Theta(i, kModeB)];
      if (derivatives == Derivatives::kNone) {
        // Values only: a mode of weight zero adds 0 f = 0 (f finite) and is not evaluated (in
        // a region or on a memory boundary one of them, or both, has weight zero: the smooth
        // fields of reduced elements).
        if (weight_a != 0.0) EvaluateMode(context, y, relay.mode_a, &mode_a_jacobian_, &mode_a_);
        if (weight_b != 0.0) EvaluateMode(context, y, relay.mode_b, &mode_b_jacobian_, &mode_b_);
        if (weight_a != 0.0 && weight_b != 0.0) {
          field_ = weight_a * mode_a_ + weight_b * mode_b_;
        } else if (weight_a != 0.0) {
          field_ = weight_a * mode_a_;
        } else if (weight_b != 0.0) {
          field_ = weight_b * mode_b_;
        } else {
          continue;  // x' += 0
        }
        out->F.head(nx) += q * field_;
        continue;
      }
      EvaluateModes(context, y, i, derivatives);
      field_ = weight_a * mode_a_ + weight_b * mode_b_;
      out->F.head(nx) += q * field_;

      const bool all = derivatives == Derivatives::kAll;
      for (int k = 0; k < kRegions; ++k) {
        out->F_z.Add(MemoryIndex(i), Theta(i, k), relay.auxiliary_gain * kMemoryDirection[k]);
        if (field_only) continue;
        const Psi& p = psi_[static_cast<std::size_t>(i)];
        out->G_y.AddBlock(Row(i, k), 0, p.d_y, -2.0 * kPointPsi[k]);
        out->G_y.Add(Row(i, k), MemoryIndex(i), -2.0 * kPointW[k]);
        if (all) {
          out->G_u.AddBlock(Row(i, k), 0, p.d_u, -2.0 * kPointPsi[k]);
          out->G_p.AddBlock(Row(i, k), 0, p.d_p, -2.0 * kPointPsi[k]);
        }
        out->G_z.Add(Row(i, k), Lambda(i, k), -1.0);
        out->G_z.Add(Row(i, k), Mu(i), -1.0);
        out->G_z.Add(Row(i, kRegions), Theta(i, k), 1.0);
        out->A_z.Add(Pair(i, k), Theta(i, k), 1.0);
        out->B_z.Add(Pair(i, k), Lambda(i, k), 1.0);
      }
      AddModeJacobian(mode_a_jacobian_, q * weight_a, out);
      AddModeJacobian(mode_b_jacobian_, q * weight_b, out);
      out->F_z.AddBlock(0, Theta(i, kModeA), mode_a_, 2.0 * q);
      out->F_z.AddBlock(0, Theta(i, kModeB), mode_b_, 2.0 * q);
      // Q_i depends on the other relays' theta_j1, theta_j4.
      for (int j = 0; j < num_relays_; ++j) {
        if (j == i) continue;
        const double dq = 2.0 * ProductExcept(i, j);
        out->F_z.AddBlock(0, Theta(j, kModeA), field_, dq);
        out->F_z.AddBlock(0, Theta(j, kModeB), field_, dq);
      }
    }
  }

  // theta is a jump variable; lambda and mu are continuous (lambda = g - min g).
  std::vector<bool> ContinuousAlgebraic() const override {
    std::vector<bool> continuous;
    for (int i = 0; i < num_relays_; ++i) {
      for (int k = 0; k < kRegions; ++k) continuous.push_back(false);
      for (int k = 0; k < kRegions + 1; ++k) continuous.push_back(true);
    }
    return continuous;
  }
  // g - lambda - mu e = 0 is differentiated; e^T theta = 1 holds on values.
  std::vector<bool> DifferentiatedEquations() const override {
    std::vector<bool> rows;
    for (int i = 0; i < num_relays_; ++i) {
      for (int k = 0; k < kRegions; ++k) rows.push_back(true);
      rows.push_back(false);
    }
    return rows;
  }

  // Row (i, k): d/d(y, u, p) [grad_y g_ik . d] = -2 z_k,psi d/d(y, u, p) [grad_y psi_i . d],
  // with grad_y psi . d = (grad input . d) / (U - L); the thresholds L, U are parameters.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    const bool all = derivatives == Derivatives::kAll;
    const int nx = num_states_;
    const int ny = context.clock_index + 1;
    const int nu = static_cast<int>(context.inputs->size());
    const int np = static_cast<int>(context.parameters->size());
    EvaluateInputs(context, y, derivatives);
    for (int i = 0; i < num_relays_; ++i) {
      const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
      const Psi& p = psi_[static_cast<std::size_t>(i)];
      // The relay input's second derivatives along d, as dense rows (one output).
      DerivativeMatrix dy, du, dp;
      dy.SetZero(1, ny, false);
      du.SetZero(1, nu, false);
      dp.SetZero(1, np, false);
      directions_.HessianDirections(context, relay.input, y, direction, derivatives);
      directions_.AddRow(0, 1.0 / p.width, 0, &dy, &du, &dp);
      if (all) {
        // d(1/(U - L))/dL = 1/(U - L)^2, d/dU = -1/(U - L)^2, times grad input . d.
        const double input_rate =
            p.width * (p.d_y.head(nx).dot(direction.head(nx)) +
                       p.d_y[context.clock_index] * direction[context.clock_index]);
        dp.Add(0, relay.lower_threshold, input_rate / (p.width * p.width));
        dp.Add(0, relay.upper_threshold, -input_rate / (p.width * p.width));
      }
      for (int k = 0; k < kRegions; ++k) {
        const double weight = -2.0 * kPointPsi[k];
        out->equation_y.AddBlock(Row(i, k), 0, dy.dense(), weight);
        if (!all) continue;
        out->equation_u.AddBlock(Row(i, k), 0, du.dense(), weight);
        out->equation_p.AddBlock(Row(i, k), 0, dp.dense(), weight);
      }
    }
  }

  // Active region (lambda = 0 kept): theta (velocity level); inactive region k:
  // lambda_k = g_k - g_a, a the relay's first active region.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    EvaluateInputs(context, y, derivatives);
    const bool all = derivatives == Derivatives::kAll;
    for (int i = 0; i < num_relays_; ++i) {
      int active = -1;
      for (int k = 0; k < kRegions && active < 0; ++k) {
        if (!a_zero[static_cast<std::size_t>(Pair(i, k))]) active = k;
      }
      MOREAU_ASSERT(active >= 0, "hysteresis statuses without an active region");
      const Psi& p = psi_[static_cast<std::size_t>(i)];
      const double w = y[MemoryIndex(i)];
      for (int k = 0; k < kRegions; ++k) {
        const int pair = Pair(i, k);
        if (!a_zero[static_cast<std::size_t>(pair)]) {
          out->values[pair] = v[Theta(i, k)];
          if (derivatives != Derivatives::kNone) out->d_v.Add(pair, Theta(i, k), 1.0);
          continue;
        }
        out->values[pair] = Indicator(k, p.value, w) - Indicator(active, p.value, w);
        if (derivatives == Derivatives::kNone) continue;
        const double d_psi = -2.0 * (kPointPsi[k] - kPointPsi[active]);
        out->d_y.AddBlock(pair, 0, p.d_y, d_psi);
        out->d_y.Add(pair, MemoryIndex(i), -2.0 * (kPointW[k] - kPointW[active]));
        if (all) {
          out->d_u.AddBlock(pair, 0, p.d_u, d_psi);
          out->d_p.AddBlock(pair, 0, p.d_p, d_psi);
        }
      }
    }
  }

  // Inactive region k of relay i: g_k - g_active, affine in psi and w, over the box.
  void IndicatorBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                       const ConstVectorRef& y_upper, const std::vector<bool>& a_zero,
                       VectorRef lower, VectorRef upper) override {
    if (!PsiBounds(context, y_lower, y_upper)) return;
    for (int i = 0; i < num_relays_; ++i) {
      int active = -1;
      for (int k = 0; k < kRegions && active < 0; ++k) {
        if (!a_zero[static_cast<std::size_t>(Pair(i, k))]) active = k;
      }
      if (active < 0) continue;
      const Interval psi = psi_bounds_[static_cast<std::size_t>(i)];
      const Interval w(y_lower[MemoryIndex(i)], y_upper[MemoryIndex(i)]);
      for (int k = 0; k < kRegions; ++k) {
        const int pair = Pair(i, k);
        if (!a_zero[static_cast<std::size_t>(pair)]) continue;
        const Interval value = (PointNormSquared(k) - PointNormSquared(active)) -
                               2.0 * (kPointPsi[k] - kPointPsi[active]) * psi -
                               2.0 * (kPointW[k] - kPointW[active]) * w;
        lower[pair] = value.lower();
        upper[pair] = value.upper();
      }
    }
  }

  // theta: the region containing (psi, w), split evenly between regions tied to round-off
  // (a point on a boundary: theta = 1/2 on each side is the sliding value), or `previous`
  // when given and the point lies on a boundary; lambda = g - min g, mu = min g.
  void InitialGuess(const BlockContext& context, const ConstVectorRef& y, const Vector* previous,
                    VectorRef z) override {
    EvaluateInputs(context, y, Derivatives::kNone);
    for (int i = 0; i < num_relays_; ++i) {
      const double psi = psi_[static_cast<std::size_t>(i)].value;
      const double w = y[MemoryIndex(i)];
      double g[kRegions];
      double g_min = std::numeric_limits<double>::infinity();
      for (int k = 0; k < kRegions; ++k) {
        g[k] = Indicator(k, psi, w);
        g_min = std::min(g_min, g[k]);
      }
      const double tie = kBoundaryTolerance * (1.0 + std::fabs(psi) + std::fabs(w));
      int tied = 0;
      for (double gk : g) tied += gk - g_min <= tie ? 1 : 0;
      const int first = Theta(i, 0);
      if (tied > 1 && previous != nullptr) {
        z.segment(first, kUnknownsPerRelay) = previous->segment(first, kUnknownsPerRelay);
        continue;
      }
      for (int k = 0; k < kRegions; ++k) {
        z[Theta(i, k)] = g[k] - g_min <= tie ? 1.0 / tied : 0.0;
        z[Lambda(i, k)] = g[k] - g_min;
      }
      z[Mu(i)] = g_min;
    }
  }

  std::vector<int> MemoryTargets(const std::vector<bool>& a_zero) const override {
    std::vector<int> targets;
    for (int i = 0; i < num_relays_; ++i) {
      targets.push_back(RelayFrozen(a_zero, i) ? (Active(a_zero, i, kToB) ? 1 : 0) : -1);
    }
    return targets;
  }

  bool AnyMemoryTarget(const std::vector<bool>& a_zero, std::size_t offset) const override {
    for (int i = 0; i < num_relays_; ++i) {
      // RelayFrozen: neither mode's theta free (both kept at zero).
      const std::size_t relay = offset + static_cast<std::size_t>(kRegions * i);
      if (a_zero[relay + std::size_t{kModeA}] && a_zero[relay + std::size_t{kModeB}]) return true;
    }
    return false;
  }

  // Some theta of every relay must be free: they sum to one.
  bool AdmitsRoles(const std::vector<PairRole>& roles) const override {
    for (int i = 0; i < num_relays_; ++i) {
      bool free = false;
      for (int k = 0; k < kRegions; ++k) {
        free |= roles[static_cast<std::size_t>(kRegions * i + k)] != PairRole::kAZero;
      }
      if (!free) return false;
    }
    return true;
  }

  // A relay switches when it enters an auxiliary region alone (physical time freezes): the
  // jump happens at that physical time. Leaving the frozen interval is not a new event.
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<Event> events;
    for (int i = 0; i < num_relays_; ++i) {
      if (RelayFrozen(before, i) || !RelayFrozen(after, i)) continue;
      events.push_back({t, EventKind::kRelaySwitch, relays_[static_cast<std::size_t>(i)].name,
                        Active(after, i, kToB) ? "A -> B" : "B -> A"});
    }
    return events;
  }

  std::vector<Event> InitialEvents(double t, const ConstVectorRef& y,
                                   const std::vector<bool>& a_zero) const override {
    std::vector<Event> events;
    for (int i = 0; i < num_relays_; ++i) {
      if (!RelayFrozen(a_zero, i)) continue;
      const HysteresisRelay& relay = relays_[static_cast<std::size_t>(i)];
      const bool to_b = Active(a_zero, i, kToB);
      const double w = y[MemoryIndex(i)];
      const std::string direction = to_b ? "A -> B" : "B -> A";
      std::string detail;
      if (w == 0.0 || w == 1.0) {
        detail = std::string("initial memory w0 = ") + (w == 1.0 ? "1" : "0") +
                 " is inconsistent with the input; re-initialized " + direction +
                 " while time is frozen";
      } else {
        detail = "starts inside a jump (w0 = " + std::to_string(w) + "), " + direction;
      }
      events.push_back({t, EventKind::kRelaySwitch, relay.name, detail});
    }
    return events;
  }

 private:
  // Boundary tie tolerance for the initial guess (round-off of a state on w = 0 or w = 1).
  static constexpr double kBoundaryTolerance = 1e-10;

  int Theta(int i, int k) const { return layout.z_offset + kUnknownsPerRelay * i + k; }
  int Lambda(int i, int k) const { return layout.z_offset + kUnknownsPerRelay * i + kRegions + k; }
  int Mu(int i) const { return layout.z_offset + kUnknownsPerRelay * i + 2 * kRegions; }
  int Row(int i, int k) const { return layout.g_offset + kEquationsPerRelay * i + k; }
  int Pair(int i, int k) const { return layout.pair_offset + kRegions * i + k; }

  // Statuses are block-local in MemoryTargets/StatusEvents/InitialEvents (pair 4 i + k).
  static bool Active(const std::vector<bool>& a_zero, int i, int k) {
    return !a_zero[static_cast<std::size_t>(kRegions * i + k)];
  }
  static bool RelayFrozen(const std::vector<bool>& a_zero, int i) {
    return !Active(a_zero, i, kModeA) && !Active(a_zero, i, kModeB);
  }

  // g_k(psi, w) = |z_k|^2 - 2 z_k . (psi, w).
  static double Indicator(int k, double psi, double w) {
    return PointNormSquared(k) - 2.0 * (kPointPsi[k] * psi + kPointW[k] * w);
  }

  // r_i = 2 (theta_i1 + theta_i4) for every relay.
  void Rates(const ConstVectorRef& z) const {
    rates_.resize(num_relays_);
    for (int i = 0; i < num_relays_; ++i) {
      rates_[i] = 2.0 * (z[Theta(i, kModeA)] + z[Theta(i, kModeB)]);
    }
  }
  // prod of r_l over l != skip1, skip2 (from the last Rates call).
  double ProductExcept(int skip1, int skip2) const {
    double product = 1.0;
    for (int l = 0; l < num_relays_; ++l) {
      if (l != skip1 && l != skip2) product *= rates_[l];
    }
    return product;
  }

  mutable Vector rates_;
  Vector field_;
};

// Discrete memories for event-driven integrators: x' += (1 - w_i) f_A,i + w_i f_B,i with
// w_i' = 0; the integrator flips w_i when the switching function (1 - psi_i while w_i = 0,
// psi_i while w_i = 1) reaches zero.
class DiscreteRelayBlock final : public RelayBlockBase {
 public:
  using RelayBlockBase::RelayBlockBase;
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<DiscreteRelayBlock>(*this);
  }
  int num_algebraic() const override { return 0; }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return 0; }
  // The mode fields are physical-time dynamics (the speed of time scales them).
  bool ScaledByClockRate() const override { return true; }
  std::vector<std::string> AlgebraicNames() const override { return {}; }
  std::vector<PairInfo> Pairs() const override { return {}; }
  std::vector<bool> ContinuousAlgebraic() const override { return {}; }
  std::vector<bool> DifferentiatedEquations() const override { return {}; }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef&,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    x_ = y.head(nx);
    for (int i = 0; i < num_relays_; ++i) {
      const double w = y[MemoryIndex(i)];
      EvaluateModes(context, y, i, derivatives);
      // x' += (1 - w) f_A + w f_B (w is 0 or 1 along solutions).
      out->F.head(nx) += (1.0 - w) * mode_a_ + w * mode_b_;
      if (derivatives == Derivatives::kNone) continue;
      AddModeJacobian(mode_a_jacobian_, 1.0 - w, out);
      AddModeJacobian(mode_b_jacobian_, w, out);
      out->F_y.AddBlock(0, MemoryIndex(i), mode_b_ - mode_a_);
    }
  }

  int num_memory_switches() const override { return num_relays_; }
  void MemorySwitchingFunctions(const BlockContext& context, const ConstVectorRef& y,
                                VectorRef out) override {
    EvaluateInputs(context, y, Derivatives::kNone);
    for (int i = 0; i < num_relays_; ++i) {
      const double psi = psi_[static_cast<std::size_t>(i)].value;
      out[i] = y[MemoryIndex(i)] < 0.5 ? 1.0 - psi : psi;
    }
  }
  void MemorySwitchingBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                             const ConstVectorRef& y_upper, VectorRef lower,
                             VectorRef upper) override {
    if (!PsiBounds(context, y_lower, y_upper)) return;
    for (int i = 0; i < num_relays_; ++i) {
      const Interval psi = psi_bounds_[static_cast<std::size_t>(i)];
      // The memory is constant between switches (w' = 0): its lower bound decides.
      const Interval value = y_lower[MemoryIndex(i)] < 0.5 ? 1.0 - psi : psi;
      lower[i] = value.lower();
      upper[i] = value.upper();
    }
  }

  void AddCurvature(const BlockContext&, const ConstVectorRef&, const ConstVectorRef&, Derivatives,
                    CurvatureTerms*) override {}
  void EventIndicators(const BlockContext&, const ConstVectorRef&, const ConstVectorRef&,
                       const std::vector<bool>&, Derivatives, IndicatorEvaluation*) override {}
  void InitialGuess(const BlockContext&, const ConstVectorRef&, const Vector*, VectorRef) override {
  }
  std::vector<Event> StatusEvents(double, const std::vector<bool>&,
                                  const std::vector<bool>&) const override {
    return {};
  }
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerHysteresis(const Scene& scene,
                                              const std::vector<HysteresisRelay>& relays) {
  return std::make_unique<HysteresisBlock>(scene, relays);
}

std::unique_ptr<LoweredBlock> LowerDiscreteRelays(const Scene& scene,
                                                  const std::vector<HysteresisRelay>& relays) {
  return std::make_unique<DiscreteRelayBlock>(scene, relays);
}

}  // namespace moreau::internal
