#include "render/frame.hpp"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include "moreau/core/error.hpp"

namespace moreau::render {

namespace {

void SetColor(cairo_t* cr, std::uint32_t rgb, double alpha = 1.0) {
  cairo_set_source_rgba(cr, ((rgb >> 16) & 0xFF) / 255.0, ((rgb >> 8) & 0xFF) / 255.0,
                        (rgb & 0xFF) / 255.0, alpha);
}

int RoundUpEven(double value) {
  const int n = static_cast<int>(std::ceil(value));
  return n + (n % 2);
}

// Closest point of segment (a, b) to p.
void ClosestOnSegment(double px, double py, const double* s, double* qx, double* qy) {
  const double dx = s[2] - s[0], dy = s[3] - s[1];
  const double length2 = dx * dx + dy * dy;
  double u = length2 > 0.0 ? ((px - s[0]) * dx + (py - s[1]) * dy) / length2 : 0.0;
  u = std::clamp(u, 0.0, 1.0);
  *qx = s[0] + u * dx;
  *qy = s[1] + u * dy;
}

constexpr double kMarginFraction = 0.05;  // of the window, on each side (FitWindow)
// Windows of points and segments more elongated than this get a scale per axis.
constexpr double kMaxUniformAspect = 3.0;

}  // namespace

struct FrameRenderer::Cairo {
  cairo_surface_t* surface = nullptr;
  cairo_t* cr = nullptr;
  ~Cairo() {
    if (cr != nullptr) cairo_destroy(cr);
    if (surface != nullptr) cairo_surface_destroy(surface);
  }
};

Image ReadPng(const std::string& path) {
  cairo_surface_t* surface = cairo_image_surface_create_from_png(path.c_str());
  if (cairo_surface_status(surface) != CAIRO_STATUS_SUCCESS) {
    cairo_surface_destroy(surface);
    ThrowInvalidArgument("cannot read PNG '", path, "'");
  }
  cairo_surface_flush(surface);
  Image image;
  image.width = cairo_image_surface_get_width(surface);
  image.height = cairo_image_surface_get_height(surface);
  const int stride = cairo_image_surface_get_stride(surface);
  const cairo_format_t format = cairo_image_surface_get_format(surface);
  const unsigned char* data = cairo_image_surface_get_data(surface);
  image.pixels.resize(static_cast<std::size_t>(image.width) *
                      static_cast<std::size_t>(image.height));
  for (int row = 0; row < image.height; ++row) {
    for (int column = 0; column < image.width; ++column) {
      std::uint32_t value = 0;
      if (format == CAIRO_FORMAT_RGB24 || format == CAIRO_FORMAT_ARGB32) {
        std::uint32_t word;
        std::memcpy(&word, data + row * stride + 4 * column, 4);
        // Premultiplied alpha: PNGs written here are opaque; compose others on white.
        const std::uint32_t a = format == CAIRO_FORMAT_ARGB32 ? (word >> 24) & 0xFF : 0xFF;
        auto channel = [&](int shift) {
          return std::min<std::uint32_t>(0xFF, ((word >> shift) & 0xFF) + (0xFF - a));
        };
        value = (channel(16) << 16) | (channel(8) << 8) | channel(0);
      }
      image.pixels[static_cast<std::size_t>(row) * static_cast<std::size_t>(image.width) +
                   static_cast<std::size_t>(column)] = value;
    }
  }
  cairo_surface_destroy(surface);
  return image;
}

FrameRenderer::FrameRenderer(const CompiledView& view, const std::vector<double>& window, int width)
    : view_(view), window_(window), cairo_(std::make_unique<Cairo>()) {
  RequireArgument(window.size() == 4 && window[0] < window[1] && window[2] < window[3],
                  "frame window must be {xmin, xmax, ymin, ymax} with xmin < xmax, ymin < ymax");
  RequireArgument(width >= 16 && width <= 8192, "frame width must be in [16, 8192] pixels, got ",
                  width);
  const double w = window[1] - window[0], h = window[3] - window[2];
  width_ = RoundUpEven(width);
  scale_ = width_ / w;
  scale_y_ = scale_;
  bool round_shapes = false;  // discs or circles: only a uniform scale keeps them round
  for (const Body& body : view.bodies()) round_shapes = round_shapes || body.radius > 0.0;
  for (const ObstacleShape& o : view.Obstacles(view.initial_time())) {
    round_shapes = round_shapes || o.shape == ViewObstacle::Shape::kCircle;
  }
  if (!round_shapes && (h > kMaxUniformAspect * w || w > kMaxUniformAspect * h)) {
    height_ = RoundUpEven(0.75 * width_);
    scale_y_ = height_ / h;
    offset_y_ = 0.0;
  } else {
    height_ = std::max(16, RoundUpEven(scale_ * h));
    offset_y_ = 0.5 * (height_ - scale_ * h);
  }
  RequireArgument(height_ <= 8192, "frame height ", height_,
                  " pixels is too large: the window's aspect ratio is extreme");
  offset_x_ = 0.0;
  cairo_->surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, width_, height_);
  cairo_->cr = cairo_create(cairo_->surface);
  trails_.resize(view.bodies().size());
}

FrameRenderer::~FrameRenderer() = default;

const unsigned char* FrameRenderer::data() const {
  return cairo_image_surface_get_data(cairo_->surface);
}
int FrameRenderer::stride() const { return cairo_image_surface_get_stride(cairo_->surface); }

void FrameRenderer::WritePng(const std::string& path) const {
  RequireArgument(cairo_surface_write_to_png(cairo_->surface, path.c_str()) == CAIRO_STATUS_SUCCESS,
                  "cannot write '", path, "'");
}

void FrameRenderer::Draw(double t, const Vector& x, bool trail_point) {
  RequireArgument(x.size() == view_.num_states(), "frame state has ", x.size(),
                  " entries, expected ", view_.num_states());
  cairo_t* cr = cairo_->cr;
  const auto& bodies = view_.bodies();
  const double diagonal = std::hypot(window_[1] - window_[0], window_[3] - window_[2]);
  // Point bodies touch within a ten-thousandth of the window (their radius is 0).
  const double point_tolerance = 1e-4 * diagonal;
  auto tolerance = [&](double r) { return std::max(kContactGapFraction * r, point_tolerance); };

  SetColor(cr, kBackgroundColor);
  cairo_paint(cr);
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);

  // Obstacles at time t.
  const std::vector<ObstacleShape> obstacles = view_.Obstacles(t);
  SetColor(cr, kObstacleColor);
  for (const ObstacleShape& o : obstacles) {
    if (o.shape == ViewObstacle::Shape::kCircle) {
      cairo_new_path(cr);
      cairo_arc(cr, Column(o.v[0]), Row(o.v[1]), std::max(1.0, scale_ * o.v[2]), 0.0, 2 * M_PI);
      cairo_fill(cr);
    } else {
      cairo_set_line_width(cr, 3.0);
      cairo_move_to(cr, Column(o.v[0]), Row(o.v[1]));
      cairo_line_to(cr, Column(o.v[2]), Row(o.v[3]));
      cairo_stroke(cr);
    }
  }

  // Trails (bodies that ask for one).
  cairo_set_line_width(cr, 1.5);
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    if (!bodies[b].trail) continue;
    auto& trail = trails_[b];
    if (trail_point) trail.emplace_back(view_.X(bodies[b], x), view_.Y(bodies[b], x));
    if (trail.size() < 2) continue;
    SetColor(cr, kBodyColor, 0.5);
    cairo_move_to(cr, Column(trail[0].first), Row(trail[0].second));
    for (const auto& [px, py] : trail) cairo_line_to(cr, Column(px), Row(py));
    cairo_line_to(cr, Column(view_.X(bodies[b], x)), Row(view_.Y(bodies[b], x)));
    cairo_stroke(cr);
  }

  // Bodies: discs (or dots for points).
  for (const Body& body : bodies) {
    const double cx = Column(view_.X(body, x)), cy = Row(view_.Y(body, x));
    const double r = std::max(2.5, scale_ * body.radius);
    cairo_new_path(cr);
    cairo_arc(cr, cx, cy, r, 0.0, 2 * M_PI);
    SetColor(cr, kBodyColor);
    cairo_fill_preserve(cr);
    SetColor(cr, 0x2F4B6B);
    cairo_set_line_width(cr, r > 6.0 ? 1.0 : 0.5);
    cairo_stroke(cr);
  }

  // Active contacts: a mark at the contact point (bodies with bodies through a cell grid of
  // side 2 max radius + tolerance, so only neighbouring cells can touch; bodies with obstacles).
  std::vector<std::pair<double, double>> marks;
  const double cell = 2.0 * view_.MaxRadius() + tolerance(view_.MaxRadius()) + point_tolerance;
  std::vector<std::pair<std::int64_t, int>> keys;
  keys.reserve(bodies.size());
  auto key = [](std::int64_t i, std::int64_t j) { return (i << 32) ^ (j & 0xFFFFFFFF); };
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const auto i = static_cast<std::int64_t>(std::floor(view_.X(bodies[b], x) / cell));
    const auto j = static_cast<std::int64_t>(std::floor(view_.Y(bodies[b], x) / cell));
    keys.emplace_back(key(i, j), static_cast<int>(b));
  }
  std::sort(keys.begin(), keys.end());
  for (std::size_t b = 0; b < bodies.size(); ++b) {
    const double xb = view_.X(bodies[b], x), yb = view_.Y(bodies[b], x), rb = bodies[b].radius;
    const auto i = static_cast<std::int64_t>(std::floor(xb / cell));
    const auto j = static_cast<std::int64_t>(std::floor(yb / cell));
    for (std::int64_t di = -1; di <= 1; ++di) {
      for (std::int64_t dj = -1; dj <= 1; ++dj) {
        const std::int64_t k = key(i + di, j + dj);
        auto range =
            std::equal_range(keys.begin(), keys.end(), std::make_pair(k, 0),
                             [](const auto& a, const auto& c) { return a.first < c.first; });
        for (auto it = range.first; it != range.second; ++it) {
          const auto other = static_cast<std::size_t>(it->second);
          if (other <= b) continue;
          const double xo = view_.X(bodies[other], x), yo = view_.Y(bodies[other], x);
          const double distance = std::hypot(xo - xb, yo - yb);
          const double ro = bodies[other].radius;
          if (distance - rb - ro <= tolerance(std::min(rb, ro)) && distance > 0.0) {
            marks.emplace_back(xb + rb * (xo - xb) / distance, yb + rb * (yo - yb) / distance);
          }
        }
      }
    }
    for (const ObstacleShape& o : obstacles) {
      double qx = 0.0, qy = 0.0, reach = 0.0;
      if (o.shape == ViewObstacle::Shape::kCircle) {
        const double d = std::hypot(xb - o.v[0], yb - o.v[1]);
        if (d <= 0.0) continue;
        qx = o.v[0] + o.v[2] * (xb - o.v[0]) / d;
        qy = o.v[1] + o.v[2] * (yb - o.v[1]) / d;
        reach = d - o.v[2];
      } else {
        ClosestOnSegment(xb, yb, o.v, &qx, &qy);
        reach = std::hypot(xb - qx, yb - qy);
      }
      if (reach - rb <= tolerance(rb)) marks.emplace_back(qx, qy);
    }
  }
  num_contacts_ = static_cast<int>(marks.size());
  const double mark = std::max(1.5, 0.3 * scale_ * view_.MaxRadius());
  SetColor(cr, kContactColor);
  for (const auto& [mx, my] : marks) {
    cairo_new_path(cr);
    cairo_arc(cr, Column(mx), Row(my), mark, 0.0, 2 * M_PI);
    cairo_fill(cr);
  }

  // The time, top left.
  char text[64];
  std::snprintf(text, sizeof text, "t = %.4g", t);
  cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, std::max(10.0, height_ / 40.0));
  SetColor(cr, 0x000000);
  cairo_move_to(cr, 8.0, 8.0 + std::max(10.0, height_ / 40.0));
  cairo_show_text(cr, text);
  cairo_surface_flush(cairo_->surface);
}

std::vector<double> FitWindow(const CompiledView& view, TrajectorySource* source) {
  if (!view.window().empty()) return view.window();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double box[4] = {kInf, -kInf, kInf, -kInf};
  auto add = [&box](double x, double y, double r) {
    box[0] = std::min(box[0], x - r);
    box[1] = std::max(box[1], x + r);
    box[2] = std::min(box[2], y - r);
    box[3] = std::max(box[3], y + r);
  };
  double t = 0.0;
  Vector x;
  while (source->Next(&t, &x)) {
    for (const Body& body : view.bodies()) add(view.X(body, x), view.Y(body, x), body.radius);
  }
  for (double time : {view.initial_time(), view.final_time()}) {
    for (const ObstacleShape& o : view.Obstacles(time)) {
      if (o.shape == ViewObstacle::Shape::kCircle) {
        add(o.v[0], o.v[1], o.v[2]);
      } else {
        add(o.v[0], o.v[1], 0.0);
        add(o.v[2], o.v[3], 0.0);
      }
    }
  }
  RequireArgument(std::isfinite(box[0]) && std::isfinite(box[2]),
                  "nothing to draw: the trajectory is empty");
  // A degenerate box (a body at rest, no obstacle) gets a unit extent.
  for (int axis = 0; axis < 2; ++axis) {
    double& lo = box[2 * axis];
    double& hi = box[2 * axis + 1];
    const double extent = std::max(hi - lo, 1e-9 * std::max(1.0, std::abs(lo)));
    const double pad = hi - lo > 0.0 ? kMarginFraction * extent : 0.5;
    lo -= pad;
    hi += pad;
  }
  return {box[0], box[1], box[2], box[3]};
}

}  // namespace moreau::render
