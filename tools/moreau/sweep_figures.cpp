#include "sweep_figures.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include "output.hpp"

namespace moreau::tool {

namespace {

// Most final states drawn (one small panel each) in a figure.
constexpr std::size_t kMaxStatePanels = 6;
// A column is constant when its finite values span at most this, relative to max(1, |value|):
// a few units of round-off in values that the integrator computes identically.
constexpr double kConstantTolerance = 1e-12;
// Bins of a histogram: about sqrt(runs), between these.
constexpr int kMinBins = 10;
constexpr int kMaxBins = 60;
// Most failed-run ticks on a figure's bottom axis (distinct varied values).
constexpr std::size_t kMaxFailedTicks = 500;

std::string Quote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("''") : std::string(1, c);
  return quoted + "'";
}

std::string FileSafe(const std::string& name) {
  std::string safe;
  for (char c : name) safe += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return safe;
}

// A quantity per run: a final state, the event count or an event time.
struct Quantity {
  std::string name;
  std::vector<double> values;  // one per row (NaN: none)
};

std::vector<Quantity> Quantities(const SweepResult& r, bool with_event_times) {
  std::vector<Quantity> quantities;
  const std::size_t shown = std::min(r.state_names.size(), kMaxStatePanels);
  for (std::size_t i = 0; i < shown; ++i) {
    Quantity q{"x." + r.state_names[i], {}};
    for (const SweepRow& row : r.rows) q.values.push_back(row.final_state[static_cast<long>(i)]);
    quantities.push_back(q);
  }
  Quantity events{"num_events", {}};
  for (const SweepRow& row : r.rows) events.values.push_back(static_cast<double>(row.num_events));
  quantities.push_back(events);
  if (with_event_times && r.num_event_times > 0) {
    Quantity first{"event_1 (first event time)", {}};
    for (const SweepRow& row : r.rows) {
      first.values.push_back(row.event_times.empty() ? NAN : row.event_times[0]);
    }
    quantities.push_back(first);
  }
  return quantities;
}

// {min, max} of the finite values, and whether they are one value.
struct Span {
  double lo = NAN, hi = NAN;
  bool constant = false;
  bool empty = true;
};
Span SpanOf(const std::vector<double>& values) {
  Span s;
  for (double v : values) {
    if (!std::isfinite(v)) continue;
    s.lo = s.empty ? v : std::min(s.lo, v);
    s.hi = s.empty ? v : std::max(s.hi, v);
    s.empty = false;
  }
  s.constant = !s.empty && s.hi - s.lo <= kConstantTolerance * std::max(1.0, std::abs(s.hi));
  return s;
}

std::string Format(double v) {
  std::ostringstream out;
  out << std::setprecision(6) << v;
  return out.str();
}

// A y range around a constant value that does not pretend to resolve round-off.
std::string ConstantRange(double v) {
  const double half = std::max(1.0, std::abs(v)) * 0.1;
  std::ostringstream out;
  out << std::setprecision(17) << "[" << v - half << ":" << v + half << "]";
  return out.str();
}

void Header(std::ofstream& s, const std::string& image, int width, int height) {
  s << "set terminal pngcairo size " << width << "," << height
    << " noenhanced font 'sans,10'\nset output " << Quote(image) << "\nset grid\n";
}

// Failed-run markers: red crosses at the quantity's value where it has one (and a red tick on
// the bottom axis at the varied value).
constexpr const char* kFailedStyle = "with points pt 2 ps 1.2 lw 2 lc rgb '#D62728'";
constexpr const char* kOkStyle = "with points pt 7 ps 0.45 lc rgb '#4C78A8'";

}  // namespace

std::vector<std::string> SweepFigures(const SweepResult& r, const SweepSpec& spec,
                                      const std::string& dir) {
  std::vector<std::string> images;
  if (r.rows.empty()) return images;
  long failed = 0;
  for (const SweepRow& row : r.rows) failed += row.success ? 0 : 1;
  const std::string failed_title = "failed runs (" + std::to_string(failed) + ")";
  const std::vector<Quantity> quantities = Quantities(r, true);

  // One figure per varied value: every quantity against it, one point per run.
  for (std::size_t v = 0; v < r.varied_names.size(); ++v) {
    const std::string base = dir + "/vs_" + FileSafe(r.varied_names[v]);
    const std::string data = base + ".dat", image = base + ".png", script = base + ".gp";
    {
      std::ofstream out(data);
      out << std::setprecision(17);
      for (std::size_t k = 0; k < r.rows.size(); ++k) {
        out << r.rows[k].values[v] << " " << (r.rows[k].success ? 1 : 0);
        for (const Quantity& q : quantities) out << " " << q.values[k];
        out << "\n";
      }
    }
    const int columns = quantities.size() > 4 ? 3 : 2;
    const int rows = static_cast<int>((quantities.size() + columns - 1) / columns);
    std::ofstream s(script);
    Header(s, image, 1200, 40 + 300 * rows);
    // Failed runs without a value (e.g. refused input) are ticks on the bottom axis.
    std::set<double> failed_at;
    for (const SweepRow& row : r.rows) {
      if (!row.success && failed_at.size() < kMaxFailedTicks) failed_at.insert(row.values[v]);
    }
    for (double x : failed_at) {
      s << std::setprecision(17) << "set arrow from " << x << ", graph 0 to " << x
        << ", graph 0.08 nohead lw 2 lc rgb '#D62728'\n";
    }
    s << "set multiplot layout " << rows << "," << columns << " title "
      << Quote(r.scene + ": " + std::to_string(r.rows.size()) + " runs against " +
               r.varied_names[v] + " (" + r.integrator + ")")
      << "\nset xlabel " << Quote(r.varied_names[v]) << "\nset key top right\n";
    for (std::size_t q = 0; q < quantities.size(); ++q) {
      const Span span = SpanOf(quantities[q].values);
      const int column = static_cast<int>(3 + q);
      s << "set title "
        << Quote(quantities[q].name + (span.constant ? " (constant: " + Format(span.lo) + ")" : ""))
        << "\nset yrange " << (span.constant ? ConstantRange(span.lo) : "[*:*]") << "\n"
        << "plot " << Quote(data) << " using 1:($2 == 1 ? $" << column << " : 1/0) " << kOkStyle
        << " title 'runs'";
      if (failed > 0) {
        s << ", " << Quote(data) << " using 1:($2 == 0 ? $" << column << " : 1/0) " << kFailedStyle
          << " title " << Quote(failed_title);
      }
      s << "\n";
    }
    s << "unset multiplot\n";
    s.close();
    if (RunGnuplot(script, image)) images.push_back(image);
  }

  // Samples: the distribution of each quantity as a histogram.
  if (!spec.samples.empty() && r.rows.size() >= 20) {
    const std::string base = dir + "/histograms";
    const std::string image = base + ".png", script = base + ".gp";
    const int columns = quantities.size() > 4 ? 3 : 2;
    const int rows = static_cast<int>((quantities.size() + columns - 1) / columns);
    std::ofstream s(script);
    Header(s, image, 1200, 40 + 280 * rows);
    s << "set multiplot layout " << rows << "," << columns << " title "
      << Quote(r.scene + ": distribution over " + std::to_string(r.rows.size()) +
               " runs (successful runs)")
      << "\nset style fill solid 0.7 noborder\nunset key\nset ylabel 'runs'\nset yrange [0:*]\n";
    const int bins = std::clamp(static_cast<int>(std::sqrt(static_cast<double>(r.rows.size()))),
                                kMinBins, kMaxBins);
    for (std::size_t q = 0; q < quantities.size(); ++q) {
      std::vector<double> ok;
      for (std::size_t k = 0; k < r.rows.size(); ++k) {
        if (r.rows[k].success && std::isfinite(quantities[q].values[k])) {
          ok.push_back(quantities[q].values[k]);
        }
      }
      const Span span = SpanOf(ok);
      const std::string data = base + "_" + std::to_string(q) + ".dat";
      std::ofstream out(data);
      out << std::setprecision(17);
      if (span.empty) {
        out << "0 0 1\n";
      } else if (span.constant) {
        out << span.lo << " " << ok.size() << " " << std::max(1.0, std::abs(span.lo)) * 0.02
            << "\n";
      } else {
        const double width = (span.hi - span.lo) / bins;
        std::vector<long> counts(static_cast<std::size_t>(bins), 0);
        for (double v : ok) {
          const int b = std::min(bins - 1, static_cast<int>((v - span.lo) / width));
          ++counts[static_cast<std::size_t>(b)];
        }
        for (int b = 0; b < bins; ++b) {
          out << span.lo + (b + 0.5) * width << " " << counts[static_cast<std::size_t>(b)] << " "
              << width << "\n";
        }
      }
      out.close();
      s << "set title "
        << Quote(quantities[q].name + (span.constant ? " (constant: " + Format(span.lo) + ")" : ""))
        << "\nset xlabel " << Quote(quantities[q].name) << "\nset xrange "
        << (span.constant ? ConstantRange(span.lo) : "[*:*]") << "\nplot " << Quote(data)
        << " using 1:2:3 with boxes lc rgb '#4C78A8'\n";
    }
    s << "unset multiplot\n";
    s.close();
    if (RunGnuplot(script, image)) images.push_back(image);
  }

  // Two grids and nothing sampled: heat maps on the grid itself.
  if (spec.grids.size() == 2 && spec.samples.empty()) {
    const SweepGrid& a = spec.grids[0];
    const SweepGrid& b = spec.grids[1];
    for (const Quantity& q : Quantities(r, false)) {
      const std::string base = dir + "/heatmap_" + FileSafe(q.name);
      const std::string data = base + ".dat", fails = base + "_failed.dat";
      const std::string image = base + ".png", script = base + ".gp";
      const Span span = SpanOf(q.values);
      {
        // Row k is grid point (i, j) with i = k / |b| (the first grid varies slowest).
        std::ofstream out(data), bad(fails);
        out << std::setprecision(17);
        bad << std::setprecision(17);
        for (std::size_t i = 0; i < a.values.size(); ++i) {
          for (std::size_t j = 0; j < b.values.size(); ++j) {
            const SweepRow& row = r.rows[i * b.values.size() + j];
            const double value = q.values[i * b.values.size() + j];
            out << a.values[i] << " " << b.values[j] << " " << (std::isfinite(value) ? value : NAN)
                << "\n";
            if (!row.success) bad << a.values[i] << " " << b.values[j] << "\n";
          }
          out << "\n";
        }
        if (failed == 0) bad << "nan nan\n";
      }
      std::ofstream s(script);
      Header(s, image, 900, 700);
      s << "set title "
        << Quote(r.scene + ": " + q.name +
                 (span.constant ? " (constant: " + Format(span.lo) + ")" : "") + " on the " +
                 std::to_string(a.values.size()) + " x " + std::to_string(b.values.size()) +
                 " grid (" + r.integrator + ")")
        << "\nset xlabel " << Quote(a.name) << "\nset ylabel " << Quote(b.name)
        << "\nset palette defined (0 '#440154', 1 '#3B528B', 2 '#21908C', 3 '#5DC863', 4 "
           "'#FDE725')\nunset grid\nset key outside bottom center\n";
      if (span.constant) {
        // One colour: no colour bar pretending to resolve round-off.
        s << "set cbrange " << ConstantRange(span.lo) << "\nunset colorbox\n";
      }
      s << "set autoscale fix\nplot " << Quote(data) << " using 1:2:3 with image notitle";
      if (failed > 0) {
        s << ", " << Quote(fails) << " using 1:2 " << kFailedStyle << " title "
          << Quote(failed_title);
      }
      s << "\n";
      s.close();
      if (RunGnuplot(script, image)) images.push_back(image);
    }
  }
  return images;
}

}  // namespace moreau::tool
