// Frames of planar scenes (render/frame.hpp, render/animation.hpp): a frame of a small crowd
// has every disc where the simulation put it at that frame's time, contacts are marked where
// the integrator's constraints are active, and trajectories stream from CSV as from memory.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"
#include "moreau/scenes/crowd.hpp"
#include "render/animation.hpp"
#include "render/frame.hpp"
#include "render/trajectory_source.hpp"
#include "render/view_geometry.hpp"

namespace moreau::render {
namespace {

namespace fs = std::filesystem;

// A crowd small enough to simulate in a fraction of a second, long enough to touch.
constexpr const char* kSmallCrowdOptions = "N=9,tf=6";
// Frames of the test animation: 13 frames over [0, 6] (every 0.5).
constexpr double kFps = 6.0;
constexpr double kDuration = 2.0;
// Pixels probed inside each disc, as a fraction of its radius in pixels: the contact marks
// (radius 0.3 r, centred on the rim) reach 0.7 r from the centre, anti-aliasing 1 px inside
// the rim.
constexpr double kProbeFraction = 0.5;
// A constraint is active in the test's check of contact marks where c <= this (the FESD
// solution puts active constraints at c = 0 to its Newton tolerance, 1e-10 and below).
constexpr double kActive = 1e-8;

fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("moreau_render_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Linear interpolation of a recorded trajectory at t (the later point at repeated times):
// written here independently of Sampler.
Vector Interpolate(const Trajectory& trajectory, double t) {
  std::size_t k = 0;
  while (k + 1 < trajectory.size() && trajectory.t[k + 1] <= t) ++k;
  if (k + 1 >= trajectory.size() || trajectory.t[k] >= t) return trajectory.x[k];
  const double s = (t - trajectory.t[k]) / (trajectory.t[k + 1] - trajectory.t[k]);
  return (1.0 - s) * trajectory.x[k] + s * trajectory.x[k + 1];
}

struct PixelMap {
  double scale, offset_y;
  std::vector<double> window;
  double Column(double x) const { return scale * (x - window[0]); }
  double Row(double y) const { return offset_y + scale * (window[3] - y); }
};
// The world-to-pixel map of a frame, from the window and the image size alone.
PixelMap MapFor(const std::vector<double>& window, const Image& image) {
  const double scale = image.width / (window[1] - window[0]);
  return {scale, 0.5 * (image.height - scale * (window[3] - window[2])), window};
}

class CrowdFrameTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(MakeScene(std::string("crowd:") + kSmallCrowdOptions));
    result_ = new SimulationResult(Simulate(*scene_, {}));
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete result_;
  }
  static Scene* scene_;
  static SimulationResult* result_;
};
Scene* CrowdFrameTest::scene_ = nullptr;
SimulationResult* CrowdFrameTest::result_ = nullptr;

TEST_F(CrowdFrameTest, EveryDiscIsAtItsComputedPosition) {
  ASSERT_TRUE(result_->success) << result_->message;
  const CompiledView view(*scene_);
  const fs::path dir = TempDir("crowd_frames");
  AnimationOptions options;
  options.fps = kFps;
  options.duration = kDuration;
  options.width = 480;
  options.frame_directory = dir.string();
  MemorySource source(result_->trajectory);
  const std::vector<double> window = view.window();
  const AnimationStats stats = Animate(view, &source, window, {}, options);
  ASSERT_EQ(stats.frames, 13);
  const double t0 = scene_->initial_time, tf = scene_->final_time;
  int contacts_seen = 0;
  for (long k : {0L, 4L, 8L, 12L}) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05ld.png", k);
    const Image image = ReadPng((dir / name).string());
    const PixelMap map = MapFor(window, image);
    const double t = t0 + (tf - t0) * k / 12.0;
    const Vector x = Interpolate(result_->trajectory, t);
    const double radius_px = map.scale * view.bodies()[0].radius;
    ASSERT_GT(radius_px, 8.0) << "discs too small for the probe";
    int inside = 0;
    for (const Body& body : view.bodies()) {
      const double cx = map.Column(x[body.x]), cy = map.Row(x[body.y]);
      // Agents that walked on past the door leave the window.
      if (cx < radius_px || cx > image.width - radius_px || cy < radius_px ||
          cy > image.height - radius_px) {
        continue;
      }
      ++inside;
      for (int probe = 0; probe <= 8; ++probe) {
        const double angle = probe * M_PI / 4.0;
        const double reach = probe == 8 ? 0.0 : kProbeFraction * radius_px;
        const int column = static_cast<int>(std::floor(cx + reach * std::cos(angle)));
        const int row = static_cast<int>(std::floor(cy + reach * std::sin(angle)));
        ASSERT_TRUE(column >= 0 && column < image.width && row >= 0 && row < image.height);
        EXPECT_EQ(image.At(column, row), kBodyColor)
            << body.name << " at t = " << t << ": pixel (" << column << ", " << row
            << ") of the disc centred at (" << cx << ", " << cy << ")";
      }
    }
    EXPECT_GE(inside, 6) << "most of the crowd is in the window at t = " << t;
    // Contact marks where the pair constraints are active.
    const MovingSet& pairs = std::get<MovingSet>(scene_->effects[0]);
    Vector c;
    pairs.constraints.Evaluate(x, Vector(), t, scene_->ParameterValues(), &c);
    const auto layout_pairs = MakeCrowdLayout(ParseCrowdOptions(kSmallCrowdOptions)).pairs;
    for (Eigen::Index j = 0; j < c.size(); ++j) {
      if (c[j] > kActive) continue;
      const auto [a, b] = layout_pairs[static_cast<std::size_t>(j)];
      const double mx = 0.5 * (x[2 * a] + x[2 * b]), my = 0.5 * (x[2 * a + 1] + x[2 * b + 1]);
      EXPECT_EQ(image.At(static_cast<int>(map.Column(mx)), static_cast<int>(map.Row(my))),
                kContactColor)
          << "active pair " << pairs.constraint_names[static_cast<std::size_t>(j)]
          << " at t = " << t;
      ++contacts_seen;
    }
  }
  EXPECT_GT(contacts_seen, 0) << "the test crowd never touched: it checks no contact mark";
}

TEST_F(CrowdFrameTest, CsvAndMemorySourcesSampleAlike) {
  const fs::path dir = TempDir("crowd_csv");
  // The CSV as `moreau run` writes it: t, states, then other columns.
  {
    std::ofstream out(dir / "trajectory.csv");
    out << "t";
    for (const std::string& name : scene_->state_names) out << "," << name;
    out << ",h\n";
    out.precision(17);
    for (std::size_t k = 0; k < result_->trajectory.size(); ++k) {
      out << result_->trajectory.t[k];
      for (Eigen::Index i = 0; i < result_->trajectory.x[k].size(); ++i) {
        out << "," << result_->trajectory.x[k][i];
      }
      out << ",0.1\n";
    }
  }
  CsvSource csv((dir / "trajectory.csv").string(), scene_->state_names);
  MemorySource memory(result_->trajectory);
  Sampler from_csv(&csv), from_memory(&memory);
  Vector a, b;
  for (double t = 0.0; t <= 6.0; t += 0.37) {
    ASSERT_TRUE(from_csv.At(t, &a));
    ASSERT_TRUE(from_memory.At(t, &b));
    EXPECT_EQ(a, b) << "t = " << t;  // 17 digits read back exactly
    EXPECT_EQ(b, Interpolate(result_->trajectory, t)) << "t = " << t;
  }
}

TEST(ViewJsonTest, RoundTripKeepsTheView) {
  const Scene scene = MakeScene("S5");
  const Scene back = SceneFromViewJson(ViewJson(scene), "view.json");
  EXPECT_EQ(back.state_names, scene.state_names);
  ASSERT_EQ(back.view.bodies.size(), 2u);
  EXPECT_EQ(back.view.bodies[1].x, "x3");
  const CompiledView a(scene), b(back);
  for (double t : {0.0, 1.5, 12.0}) {
    const auto oa = a.Obstacles(t), ob = b.Obstacles(t);
    ASSERT_EQ(oa.size(), ob.size());
    for (std::size_t k = 0; k < oa.size(); ++k) {
      for (int i = 0; i < 3; ++i) EXPECT_EQ(oa[k].v[i], ob[k].v[i]);
    }
    EXPECT_EQ(oa[0].v[0], std::cos(t) + 8.0);  // the right disc's centre moves with cos t
  }
  EXPECT_THROW(SceneFromViewJson(nlohmann::json::object(), "bad.json"), std::invalid_argument);
}

TEST(CompiledViewTest, SceneWithoutBodiesIsRefused) {
  EXPECT_THROW(CompiledView(MakeScene("F1")), std::invalid_argument);
}

}  // namespace
}  // namespace moreau::render
