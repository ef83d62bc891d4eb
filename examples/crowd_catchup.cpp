// Maury and Venel's catch-up scheme on a crowd scene (docs/crowd-motion.md): a cheap,
// first-order estimate of how many contacts form, at sizes that moreau's integrators do not
// reach yet, and a check of the scene's fixed neighbour list. Every step projects the desired
// velocity on the velocities that keep the linearized constraints,
//
//   v = argmin |v - U(q)|^2  subject to  c_k(q) + h grad c_k(q) . v >= 0,   q <- q + h v
//
// (B. Maury, J. Venel, "A discrete contact model for crowd motion", ESAIM: M2AN 45, 2011,
// Sec. 4), by projected Gauss-Seidel on the multipliers, warm-started from the previous step.
// The constraints are those of the scene's functions (same scaling), but for *every* pair and
// wall within reach, found by a cell grid at every step; pairs outside the scene's fixed list
// that ever touch are counted. Not an integrator of moreau: no error control, order 1.
//
//   crowd_catchup [KEY=VALUE ...] [--h H] [--every T]
//
// KEY=VALUE are the crowd options of the scene name (N=10000 seed=3 tf=20 ...), --h the step
// (default 0.01 radius / speed), --every the reporting interval (default tf / 10).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "moreau/scenes/crowd.hpp"

namespace {

using moreau::CrowdLayout;
using moreau::CrowdWall;
using moreau::Vector;

constexpr CrowdWall kWalls[] = {CrowdWall::kLeft, CrowdWall::kBottom, CrowdWall::kTop,
                                CrowdWall::kUpperJamb, CrowdWall::kLowerJamb};
// Multipliers converge when no linearized constraint is violated by more than this, relative to
// the speed, and no active one is slack by more (velocity units).
constexpr double kResidualTolerance = 1e-7;
constexpr int kMaxSweeps = 20000;

// One linearized constraint c + h g . v >= 0, g with entries on agents i (and j for a pair).
struct Row {
  std::uint64_t key;  // pairs: i N + j; walls: N^2 + 5 i + wall
  int i, j;           // j < 0: a wall
  double c;
  double gi[2], gj[2];
  double norm2;
  double lambda;
};

struct StepReport {
  int active_pairs = 0, active_walls = 0, agents_in_contact = 0, unlisted_active = 0;
  int sweeps = 0;
  double residual = 0.0;
};

class CatchUp {
 public:
  CatchUp(const CrowdLayout& layout, double h) : layout_(layout), h_(h), q_(layout.initial_state) {
    const auto& o = layout.options;
    r_ = o.radius;
    margin_ = std::max(r_, 8.0 * h * o.speed);
    n_ = layout.num_agents();
  }

  const Vector& q() const { return q_; }
  const std::unordered_set<std::uint64_t>& ever_active_pairs() const { return ever_active_; }
  // Largest initial centre distance of a pair that has been in contact so far.
  double farthest_contact() const { return farthest_; }

  StepReport Step() {
    const auto& o = layout_.options;
    const int n = n_;
    // Desired velocity (as the scene's dynamics).
    Vector u(2 * n);
    for (int i = 0; i < n; ++i) {
      const double dx = layout_.exit_x - q_[2 * i], dy = 0.0 - q_[2 * i + 1];
      const double norm = std::sqrt(dx * dx + dy * dy + o.smoothing * o.smoothing);
      u[2 * i] = o.speed * dx / norm;
      u[2 * i + 1] = o.speed * dy / norm;
    }
    BuildRows();
    Vector v = u;
    for (const Row& row : rows_) Apply(row, row.lambda, &v);
    StepReport report;
    for (report.sweeps = 1; report.sweeps <= kMaxSweeps; ++report.sweeps) {
      double residual = 0.0;
      for (Row& row : rows_) {
        const double a = row.c / h_ + Dot(row, v);  // >= 0 wanted, = 0 where lambda > 0
        const double lambda = std::max(0.0, row.lambda - a / row.norm2);
        residual = std::max(residual, row.lambda > 0.0 ? std::abs(a) : std::max(0.0, -a));
        Apply(row, lambda - row.lambda, &v);
        row.lambda = lambda;
      }
      report.residual = residual;
      if (residual <= kResidualTolerance * o.speed) break;
    }
    q_ += h_ * v;
    std::vector<char> in_contact(static_cast<std::size_t>(n), 0);
    previous_.clear();
    for (const Row& row : rows_) {
      previous_[row.key] = row.lambda;
      if (row.lambda <= 0.0) continue;
      in_contact[static_cast<std::size_t>(row.i)] = 1;
      if (row.j < 0) {
        ++report.active_walls;
        continue;
      }
      in_contact[static_cast<std::size_t>(row.j)] = 1;
      ++report.active_pairs;
      if (ever_active_.insert(row.key).second) {
        const Vector& q0 = layout_.initial_state;
        farthest_ = std::max(farthest_, std::hypot(q0[2 * row.i] - q0[2 * row.j],
                                                   q0[2 * row.i + 1] - q0[2 * row.j + 1]));
      }
      if (!std::binary_search(layout_.pairs.begin(), layout_.pairs.end(),
                              std::make_pair(row.i, row.j))) {
        ++report.unlisted_active;
      }
    }
    report.agents_in_contact =
        static_cast<int>(std::count(in_contact.begin(), in_contact.end(), 1));
    return report;
  }

 private:
  double Dot(const Row& row, const Vector& v) const {
    double d = row.gi[0] * v[2 * row.i] + row.gi[1] * v[2 * row.i + 1];
    if (row.j >= 0) d += row.gj[0] * v[2 * row.j] + row.gj[1] * v[2 * row.j + 1];
    return d;
  }
  static void Apply(const Row& row, double dlambda, Vector* v) {
    (*v)[2 * row.i] += dlambda * row.gi[0];
    (*v)[2 * row.i + 1] += dlambda * row.gi[1];
    if (row.j >= 0) {
      (*v)[2 * row.j] += dlambda * row.gj[0];
      (*v)[2 * row.j + 1] += dlambda * row.gj[1];
    }
  }
  double Warm(std::uint64_t key) const {
    const auto found = previous_.find(key);
    return found == previous_.end() ? 0.0 : found->second;
  }

  // Every pair and wall constraint within margin_ of contact, with the scene's scaling.
  void BuildRows() {
    rows_.clear();
    const std::uint64_t n = static_cast<std::uint64_t>(n_);
    for (const auto& [i, j] : moreau::FindCrowdPairs(q_, 2.0 * r_ + margin_)) {
      const double dx = q_[2 * i] - q_[2 * j], dy = q_[2 * i + 1] - q_[2 * j + 1];
      const double s = 1.0 / (2.0 * r_);
      Row row{static_cast<std::uint64_t>(i) * n + static_cast<std::uint64_t>(j),
              i,
              j,
              (dx * dx + dy * dy - 4.0 * r_ * r_) / (4.0 * r_),
              {dx * s, dy * s},
              {-dx * s, -dy * s},
              2.0 * (dx * dx + dy * dy) * s * s,
              0.0};
      row.lambda = Warm(row.key);
      rows_.push_back(row);
    }
    const double jamb = layout_.jamb_radius + r_;
    for (int i = 0; i < n_; ++i) {
      for (int w = 0; w < 5; ++w) {
        if (layout_.WallGap(q_, i, kWalls[w]) >= margin_) continue;
        Row row{n * n + 5 * static_cast<std::uint64_t>(i) + static_cast<std::uint64_t>(w),
                i,
                -1,
                0.0,
                {0.0, 0.0},
                {0.0, 0.0},
                1.0,
                0.0};
        const double x = q_[2 * i], y = q_[2 * i + 1];
        switch (kWalls[w]) {
          case CrowdWall::kLeft:
            row.c = x - r_;
            row.gi[0] = 1.0;
            break;
          case CrowdWall::kBottom:
            row.c = y + 0.5 * layout_.room_height - r_;
            row.gi[1] = 1.0;
            break;
          case CrowdWall::kTop:
            row.c = 0.5 * layout_.room_height - r_ - y;
            row.gi[1] = -1.0;
            break;
          default: {
            const double cy =
                kWalls[w] == CrowdWall::kUpperJamb ? layout_.upper_jamb_y : -layout_.upper_jamb_y;
            const double dx = x - layout_.door_x, dy = y - cy;
            row.c = (dx * dx + dy * dy - jamb * jamb) / (2.0 * jamb);
            row.gi[0] = dx / jamb;
            row.gi[1] = dy / jamb;
            row.norm2 = row.gi[0] * row.gi[0] + row.gi[1] * row.gi[1];
          }
        }
        row.lambda = Warm(row.key);
        rows_.push_back(row);
      }
    }
  }

  const CrowdLayout& layout_;
  double h_, r_ = 0.0, margin_ = 0.0, farthest_ = 0.0;
  int n_ = 0;
  Vector q_;
  std::vector<Row> rows_;
  std::unordered_map<std::uint64_t, double> previous_;
  std::unordered_set<std::uint64_t> ever_active_;
};

}  // namespace

int main(int argc, char** argv) {
  try {
    std::string options_text;
    double h = 0.0, every = 0.0;
    for (int k = 1; k < argc; ++k) {
      const std::string argument = argv[k];
      if ((argument == "--h" || argument == "--every") && k + 1 < argc) {
        (argument == "--h" ? h : every) = std::stod(argv[++k]);
      } else if (argument.find('=') != std::string::npos) {
        options_text += (options_text.empty() ? "" : ",") + argument;
      } else {
        std::fprintf(stderr, "usage: crowd_catchup [KEY=VALUE ...] [--h H] [--every T]\n");
        return 2;
      }
    }
    const moreau::CrowdOptions options = moreau::ParseCrowdOptions(options_text);
    const CrowdLayout layout = moreau::MakeCrowdLayout(options);
    if (h <= 0.0) h = 0.01 * options.radius / options.speed;
    if (every <= 0.0) every = options.final_time / 10.0;
    const moreau::CrowdCertificate start = moreau::CertifyCrowdState(layout, layout.initial_state);
    std::printf(
        "crowd N = %d: room %g x %g, door %g at x = %g, exit x = %g; %zu listed pairs, "
        "%zu wall constraints\nstart: %s\nh = %g\n",
        options.agents, layout.grid_length, layout.room_height, layout.door_width, layout.door_x,
        layout.exit_x, layout.pairs.size(), layout.walls.size(), start.Summary().c_str(), h);
    std::printf("%8s %8s %8s %8s %9s %9s %12s %12s %8s %10s %8s\n", "t", "pairs", "walls", "agents",
                "unlisted", "farthest", "min_gap", "min_unl_gap", "sweeps", "residual", "cpu_s");
    CatchUp scheme(layout, h);
    const auto started = std::chrono::steady_clock::now();
    const int steps = static_cast<int>(std::ceil(options.final_time / h - 1e-9));
    const int report_every = std::max(1, static_cast<int>(std::lround(every / h)));
    int max_sweeps = 0;
    double max_residual = 0.0;
    for (int step = 1; step <= steps; ++step) {
      const StepReport report = scheme.Step();
      max_sweeps = std::max(max_sweeps, report.sweeps);
      max_residual = std::max(max_residual, report.residual);
      if (step % report_every != 0 && step != steps) continue;
      const moreau::CrowdCertificate c = moreau::CertifyCrowdState(layout, scheme.q());
      const double cpu =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
      std::printf("%8.3f %8d %8d %8d %9d %9.3f %12.3e %12.3e %8d %10.2e %8.1f\n", step * h,
                  report.active_pairs, report.active_walls, report.agents_in_contact,
                  report.unlisted_active, scheme.farthest_contact(), c.min_pair_gap,
                  c.min_unlisted_pair_gap, max_sweeps, max_residual, cpu);
      max_sweeps = 0;
      max_residual = 0.0;
    }
    // Initial centre distances of the pairs that were ever in contact: the cutoff they need.
    double farthest = 0.0;
    int unlisted = 0;
    const auto n = static_cast<std::uint64_t>(options.agents);
    for (const std::uint64_t key : scheme.ever_active_pairs()) {
      const int i = static_cast<int>(key / n), j = static_cast<int>(key % n);
      const Vector& q0 = layout.initial_state;
      farthest =
          std::max(farthest, std::hypot(q0[2 * i] - q0[2 * j], q0[2 * i + 1] - q0[2 * j + 1]));
      if (!std::binary_search(layout.pairs.begin(), layout.pairs.end(), std::make_pair(i, j))) {
        ++unlisted;
      }
    }
    std::printf(
        "pairs ever in contact: %zu, %d of them outside the fixed list (cutoff %g); the "
        "farthest started %g apart\n",
        scheme.ever_active_pairs().size(), unlisted, options.cutoff, farthest);
    return 0;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "crowd_catchup: error: %s\n", error.what());
    return 2;
  }
}
