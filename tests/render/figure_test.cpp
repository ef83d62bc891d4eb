// The per-run figure of `moreau run` (tools/moreau/run_figure.cpp), opened and checked: the
// phase portrait of S3 draws the floor at x2 = -1 (pixels against the panel's geometry), the
// figure of H1 shows the temperature and the relay but none of the time-freezing variables,
// and the time axes end at tf.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "../problems/reference_problems.hpp"
#include "../tools/run_cli.hpp"
#include "render/frame.hpp"

namespace moreau::render {
namespace {

namespace fs = std::filesystem;
using moreau::testing::RunCli;

fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("moreau_figure_" + name);
  fs::remove_all(dir);
  return dir;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::uint32_t Parse(const std::string& hex) {
  return static_cast<std::uint32_t>(std::stoul(hex.substr(1), nullptr, 16));
}

// Rows of the image around a curve's position that may hold its colour: gnuplot draws a 2 px
// line centred on the position (lw 2), anti-aliased over one more pixel on each side.
constexpr int kLineHalfWidth = 2;

// Per channel: the boundary is many short segments whose anti-aliased ends overlap, so the
// line's core is its colour to a few units (measured: at most 3 off).
constexpr int kColourTolerance = 8;

bool Matches(std::uint32_t a, std::uint32_t b) {
  for (int shift : {0, 8, 16}) {
    const int ca = static_cast<int>((a >> shift) & 0xFF),
              cb = static_cast<int>((b >> shift) & 0xFF);
    if (std::abs(ca - cb) > kColourTolerance) return false;
  }
  return true;
}

// Whether the boundary colour is in the column within the line's half width of `row`.
bool ColourNear(const Image& image, int column, double row, std::uint32_t colour) {
  for (int r = static_cast<int>(std::floor(row)) - kLineHalfWidth;
       r <= static_cast<int>(std::ceil(row)) + kLineHalfWidth; ++r) {
    if (r >= 0 && r < image.height && Matches(image.At(column, r), colour)) return true;
  }
  return false;
}

TEST(RunFigureTest, PhasePortraitOfS3HasTheFloorAtMinusOne) {
  const fs::path dir = TempDir("S3");
  const auto outcome = RunCli("run S3 --quiet --out " + dir.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  const Image image = ReadPng((dir / "trajectory.png").string());
  const nlohmann::json figure = nlohmann::json::parse(ReadText(dir / "figure.json"));
  ASSERT_TRUE(figure.contains("phase")) << "a two-state scene gets a phase portrait";
  const auto& phase = figure["phase"];
  ASSERT_EQ(image.width, figure["width"].get<int>());
  ASSERT_EQ(image.height, figure["height"].get<int>());
  const double left = phase["left"], right = phase["right"], top = phase["top"],
               bottom = phase["bottom"];
  const double x_lo = phase["xrange"][0], x_hi = phase["xrange"][1];
  const double y_lo = phase["yrange"][0], y_hi = phase["yrange"][1];
  const std::uint32_t colour = Parse(phase["boundary_color"].get<std::string>());
  auto column_of = [&](double x) { return left + (x - x_lo) / (x_hi - x_lo) * (right - left); };
  auto row_of = [&](double y) { return top + (y_hi - y) / (y_hi - y_lo) * (bottom - top); };
  // The floor where the trajectory does not cover it: x1 < -0.4 (the last arc meets the floor
  // tangentially at x1 = 0) and x1 > 1.85 (the first arc hits it at sqrt 3 from above).
  int checked = 0;
  for (double x1 = x_lo + 0.03 * (x_hi - x_lo); x1 < x_hi - 0.03 * (x_hi - x_lo); x1 += 0.02) {
    if (x1 > -0.4 && x1 < 1.85) continue;
    const int column = static_cast<int>(column_of(x1));
    EXPECT_TRUE(ColourNear(image, column, row_of(-1.0), colour))
        << "no floor at x1 = " << x1 << ", x2 = -1 (column " << column << ", row " << row_of(-1.0)
        << ")";
    // ... and not anywhere else in the column (only one boundary, at the floor).
    for (double x2 : {-1.25, -0.75, 0.0, 1.0}) {
      EXPECT_FALSE(ColourNear(image, column, row_of(x2), colour))
          << "boundary colour at x1 = " << x1 << ", x2 = " << x2;
    }
    ++checked;
  }
  EXPECT_GT(checked, 20);
  // The time axes end at tf = 11 pi / 12 + sqrt 3 (the final time the integrator reached: tf up
  // to the round-off of summing 94 element lengths).
  const std::string script = ReadText(dir / "plot.gp");
  const std::string key = "set xrange [0:";
  const std::size_t at = script.find(key);
  ASSERT_NE(at, std::string::npos) << script;
  const double axis_end = std::stod(script.substr(at + key.size()));
  constexpr double kEndTolerance = 1e-12;
  EXPECT_NEAR(axis_end, 11.0 * M_PI / 12.0 + std::sqrt(3.0), kEndTolerance);
  // Events are labelled by their constraint and kind.
  EXPECT_NE(script.find("'floor.c'"), std::string::npos);
  EXPECT_NE(script.find("title 'enter'"), std::string::npos);
  EXPECT_NE(script.find("title 'leave'"), std::string::npos);
}

// The states are drawn along FESD's collocation polynomials (curves.dat), not as a polygon
// through the step points: S3 with the default error control takes 17 elements, and the
// polygon through them is 1.9e-2 off the closed form between the points (a pixel of the
// 230-pixel state panel spanning 4), the drawn curve 1.3e-5 (measured).
TEST(RunFigureTest, CurvesFollowTheCollocationPolynomials) {
  const fs::path dir = TempDir("S3_curves");
  const auto outcome = RunCli("run S3 --quiet --out " + dir.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  const testing::ReferenceProblem s3 = testing::S3();
  std::ifstream curves(dir / "curves.dat");
  std::string line;
  int points = 0;
  double largest = 0.0;
  while (std::getline(curves, line)) {
    double t = 0.0, x1 = 0.0, x2 = 0.0;
    char comma = 0;
    std::istringstream row(line);
    ASSERT_TRUE(row >> t >> comma >> x1 >> comma >> x2) << line;
    const Vector exact = s3.solution(t);
    largest = std::max({largest, std::fabs(x1 - exact[0]), std::fabs(x2 - exact[1])});
    ++points;
  }
  // O(h^(s+1)) between the nodes for the default tolerance's steps: a hundredth of a pixel.
  constexpr double kCurveTolerance = 1e-4;
  EXPECT_LE(largest, kCurveTolerance);
  // Twelve points inside each element besides its three stages.
  const std::string trajectory = ReadText(dir / "trajectory.csv");
  const auto steps = std::count(trajectory.begin(), trajectory.end(), '\n') - 1;
  EXPECT_GE(points, 10 * steps) << steps << " steps";
  // The multipliers as lines through the stage values: lambda = x1 on the floor, decreasing
  // linearly to 0 at the leave, drawn without steps (every stage row within the tolerance; at
  // the switches, within the run's switch-time accuracy, the rows of the jump itself).
  std::ifstream multipliers(dir / "multipliers.csv");
  int on_floor = 0;
  while (std::getline(multipliers, line)) {
    double t = 0.0, lambda = 0.0;
    char comma = 0;
    std::istringstream row(line);
    ASSERT_TRUE(row >> t >> comma >> lambda) << line;
    constexpr double kSwitchWindow = 1e-5;
    if (t <= s3.switch_times[0] + kSwitchWindow || t >= s3.switch_times[1] - kSwitchWindow) {
      continue;
    }
    EXPECT_NEAR(lambda, s3.solution(t)[0], kCurveTolerance) << "t = " << t;
    ++on_floor;
  }
  EXPECT_GT(on_floor, 5);
}

TEST(RunFigureTest, H1FigureHasNoInternalVariable) {
  const fs::path dir = TempDir("H1");
  const auto outcome = RunCli("run H1 --quiet --out " + dir.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  ASSERT_TRUE(fs::exists(dir / "trajectory.png"));
  // trajectory.csv keeps the lowering's variables; the figure draws none of them.
  const std::string csv_header = ReadText(dir / "trajectory.csv").substr(0, 200);
  ASSERT_NE(csv_header.find("theta_mode_A"), std::string::npos);
  const std::string script = ReadText(dir / "plot.gp");
  for (const char* internal : {"theta", "lambda_mode", "lambda_to", ".mu"}) {
    EXPECT_EQ(script.find(internal), std::string::npos) << internal << " in\n" << script;
  }
  // What it does show: the temperature with its unit and the relay's memory as a band.
  EXPECT_NE(script.find("temperature (x) [°C]"), std::string::npos) << script;
  EXPECT_NE(script.find("thermostat: w = 1"), std::string::npos) << script;
  // Asked for, the internal variables are there.
  const auto internal = RunCli("run H1 --quiet --plot-internal --out " + dir.string());
  ASSERT_EQ(internal.exit_code, 0) << internal.output;
  EXPECT_NE(ReadText(dir / "plot.gp").find("theta_mode_A"), std::string::npos);
}

TEST(AnimateCommandTest, WritesVideoGifAndSnapshots) {
  const fs::path dir = TempDir("S5");
  const auto outcome = RunCli(
      "run S5 --quiet --animate --fps 5 --duration 2 --width 160 "
      "--gif-width 80 --out " +
      dir.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  for (const char* file : {"animation.mp4", "animation.gif", "view.json"}) {
    EXPECT_GT(fs::exists(dir / file) ? fs::file_size(dir / file) : 0u, 100u) << file;
  }
  int snapshots = 0;
  for (const auto& entry : fs::directory_iterator(dir / "snapshots")) {
    snapshots += entry.path().extension() == ".png";
  }
  EXPECT_GT(snapshots, 0) << "S5 has contact events";
  // `moreau animate` on the run directory (the trajectory streamed from CSV) does the same.
  fs::remove(dir / "animation.gif");
  const auto again = RunCli("animate " + dir.string() +
                            " --fps 5 --duration 2 --width 160 "
                            "--gif-width 80 --no-mp4");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_TRUE(fs::exists(dir / "animation.gif"));
}

TEST(AnimateCommandTest, SceneWithoutViewIsAClearError) {
  const auto outcome = RunCli("run F1 --quiet --animate --out " + TempDir("F1").string());
  EXPECT_EQ(outcome.exit_code, 2);
  EXPECT_NE(outcome.output.find("declares no bodies"), std::string::npos) << outcome.output;
  const auto missing = RunCli("animate " + TempDir("none").string());
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.output.find("not a run directory"), std::string::npos) << missing.output;
}

}  // namespace
}  // namespace moreau::render
