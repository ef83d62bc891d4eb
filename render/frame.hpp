#pragma once
// One frame of a planar scene drawn with cairo into memory: obstacles at time t, each body as
// a disc (or a point) at its state's position, contacts marked where they are active, the
// bodies' trails, and the time. The world-to-pixel map is a uniform scale (circles stay
// circles) fitting the window into the image with a margin.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "render/trajectory_source.hpp"
#include "render/view_geometry.hpp"

namespace moreau::render {

// A body touches another body or an obstacle when their gap is at most this fraction of its
// radius (an active constraint has gap 0 up to the solver's tolerance; the frame's state is
// interpolated between recorded points): at 10 px per radius, a fifth of a pixel.
inline constexpr double kContactGapFraction = 0.02;

// Colours (0xRRGGBB) that tests and captions refer to.
inline constexpr std::uint32_t kBackgroundColor = 0xFFFFFF;
inline constexpr std::uint32_t kBodyColor = 0x4C78A8;      // disc fill
inline constexpr std::uint32_t kObstacleColor = 0x555555;  // walls, moving boundaries
inline constexpr std::uint32_t kContactColor = 0xE45756;   // active contact marks

// An RGB image (0xRRGGBB per pixel, row-major, top row first).
struct Image {
  int width = 0;
  int height = 0;
  std::vector<std::uint32_t> pixels;
  std::uint32_t At(int column, int row) const {
    return pixels[static_cast<std::size_t>(row) * static_cast<std::size_t>(width) +
                  static_cast<std::size_t>(column)];
  }
};
// Reads a PNG (std::invalid_argument if it cannot).
Image ReadPng(const std::string& path);

class FrameRenderer {
 public:
  // window = {xmin, xmax, ymin, ymax} in world units; the image is `width` pixels wide and as
  // high as the window's aspect ratio needs (both rounded up to even numbers, as video
  // encoders want). A view of points and segments only whose window is far from square (a
  // phase plane of quantities in different units) gets a 4:3 image with a scale per axis.
  FrameRenderer(const CompiledView& view, const std::vector<double>& window, int width);
  ~FrameRenderer();
  FrameRenderer(const FrameRenderer&) = delete;
  FrameRenderer& operator=(const FrameRenderer&) = delete;

  // Draws the frame of time t with the state x. `trail_point` adds the bodies' current
  // positions to their trails (frames do; snapshots between frames do not).
  void Draw(double t, const Vector& x, bool trail_point = true);
  // Number of active contacts found by the last Draw (body-body pairs and body-obstacle).
  int num_contacts() const { return num_contacts_; }

  int width() const { return width_; }
  int height() const { return height_; }
  // The frame as BGRA bytes (cairo's ARGB32 on a little-endian machine), `stride` per row.
  const unsigned char* data() const;
  int stride() const;
  void WritePng(const std::string& path) const;
  // Pixel coordinates (column, row; fractional, row 0 at the top) of world point (x, y).
  double Column(double x) const { return offset_x_ + scale_ * (x - window_[0]); }
  double Row(double y) const { return offset_y_ + scale_y_ * (window_[3] - y); }
  double scale() const { return scale_; }  // pixels per world unit (x; y too unless stretched)

 private:
  struct Cairo;
  const CompiledView& view_;
  std::vector<double> window_;
  int width_ = 0, height_ = 0;
  double scale_ = 1.0, scale_y_ = 1.0, offset_x_ = 0.0, offset_y_ = 0.0;
  std::unique_ptr<Cairo> cairo_;
  std::vector<std::vector<std::pair<double, double>>> trails_;
  int num_contacts_ = 0;
};

// The window {xmin, xmax, ymin, ymax} a view shows: its declared window, else the bounding
// box of the bodies (with their radii) over the whole trajectory and of the obstacles at t0
// and tf, enlarged by 5%.
std::vector<double> FitWindow(const CompiledView& view, TrajectorySource* source);

}  // namespace moreau::render
