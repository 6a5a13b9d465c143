#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string_view>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/io/file.h>
#include <avp/report/svg_plot.h>

namespace avp::report {

namespace {

// Layout, pixels.
constexpr double kMarginLeft = 72.0;
constexpr double kMarginRightPlain = 24.0;
constexpr double kMarginRightAxis = 72.0;
constexpr double kMarginTop = 44.0;
constexpr double kAxisBelow = 58.0;  ///< x tick labels and the x label, under the plot area
constexpr double kLegendRow = 20.0;
constexpr double kCharWidth = 7.0;  ///< estimated width of one character at 12 px
constexpr int kTargetTicks = 6;
constexpr int kTargetIntegerTicks = 10;  ///< views: every one up to ten

constexpr std::array<std::string_view, 10> kPalette = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728",
                                                       "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                                                       "#bcbd22", "#17becf"};

/// A data interval and its ticks.
struct Axis {
  double lo = 0.0;
  double hi = 1.0;
  double step = 0.2;
  std::vector<double> ticks;
  int decimals = 1;
};

/// 1, 2 or 5 times a power of ten, the nearest at or above `raw`.
double NiceStep(double raw) {
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / p;
  if (f <= 1.0) return p;
  if (f <= 2.0) return 2.0 * p;
  if (f <= 5.0) return 5.0 * p;
  return 10.0 * p;
}

/// Ticks over [lo, hi]: fixed ends stay, free ends are widened to whole steps.
Axis MakeAxis(double lo, double hi, bool fixed_lo, bool fixed_hi, bool integer) {
  if (!(hi > lo)) {  // one value (or none): a unit interval around it
    const double pad = integer ? 1.0 : (lo == 0.0 ? 1.0 : 0.5 * std::abs(lo));
    if (!fixed_lo) lo -= pad;
    if (!fixed_hi) hi += pad;
    if (!(hi > lo)) hi = lo + pad;
  }
  Axis a;
  a.step = NiceStep((hi - lo) / (integer ? kTargetIntegerTicks : kTargetTicks));
  if (integer) a.step = std::max(1.0, std::round(a.step));
  if (integer) {  // half a unit of room so that the first and last points are not on the frame
    a.lo = fixed_lo ? lo : lo - 0.5;
    a.hi = fixed_hi ? hi : hi + 0.5;
  } else {
    a.lo = fixed_lo ? lo : std::floor(lo / a.step + 1e-9) * a.step;
    a.hi = fixed_hi ? hi : std::ceil(hi / a.step - 1e-9) * a.step;
  }
  const double first = std::ceil(a.lo / a.step - 1e-9) * a.step;
  for (int i = 0;; ++i) {
    const double t = first + i * a.step;
    if (t > a.hi + 1e-9 * a.step || i > 1000) break;
    a.ticks.push_back(t);
  }
  a.decimals = std::max(0, -static_cast<int>(std::floor(std::log10(a.step) + 1e-9)));
  return a;
}

std::string TickLabel(double v, int decimals) {
  if (std::abs(v) < 1e-12) v = 0.0;  // no "-0"
  return fmt::format("{:.{}f}", v, decimals);
}

std::string Num(double v) { return fmt::format("{:.2f}", v); }

/// Finite data range of the series on one axis (bands included).
std::pair<double, double> DataRange(const LinePlot& plot, bool right) {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -lo;
  for (const LineSeries& s : plot.series) {
    if (s.right_axis != right) continue;
    for (size_t i = 0; i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      lo = std::min(lo, s.y[i]);
      hi = std::max(hi, s.y[i]);
      if (i < s.band_lo.size() && std::isfinite(s.band_lo[i]) && std::isfinite(s.band_hi[i])) {
        lo = std::min(lo, s.band_lo[i]);
        hi = std::max(hi, s.band_hi[i]);
      }
    }
  }
  if (lo > hi) return {0.0, 1.0};
  return {lo, hi};
}

Axis MakeYAxis(const LinePlot& plot, bool right) {
  const double fixed_lo = right ? plot.y2_min : plot.y_min;
  const double fixed_hi = right ? plot.y2_max : plot.y_max;
  auto [lo, hi] = DataRange(plot, right);
  if (std::isfinite(fixed_lo)) lo = fixed_lo;
  if (std::isfinite(fixed_hi)) hi = fixed_hi;
  if (std::isfinite(fixed_lo) && !std::isfinite(fixed_hi)) hi = std::max(hi, lo);
  if (std::isfinite(fixed_hi) && !std::isfinite(fixed_lo)) lo = std::min(lo, hi);
  return MakeAxis(lo, hi, std::isfinite(fixed_lo), std::isfinite(fixed_hi), false);
}

/// Runs of consecutive indices where `ok(i)` holds.
template <typename F>
std::vector<std::pair<size_t, size_t>> Runs(size_t n, F&& ok) {
  std::vector<std::pair<size_t, size_t>> runs;
  size_t i = 0;
  while (i < n) {
    if (!ok(i)) {
      ++i;
      continue;
    }
    size_t j = i;
    while (j + 1 < n && ok(j + 1)) ++j;
    runs.emplace_back(i, j);
    i = j + 1;
  }
  return runs;
}

// ---- Stages of RenderLinePlotSvg ----------------------------------------------------------------

/// A legend entry: series index, left edge (px) and row. Entries flow left to right under the x
/// label.
struct LegendEntry {
  size_t series;
  double x;
  int row;
};

/// Legend entries of the named series, wrapped into rows between `left` and `right` (px).
std::vector<LegendEntry> LegendLayout(const LinePlot& plot, double left, double right) {
  std::vector<LegendEntry> legend;
  double x = left;
  int row = 0;
  for (size_t k = 0; k < plot.series.size(); ++k) {
    if (plot.series[k].name.empty()) continue;
    const double w = 34.0 + kCharWidth * static_cast<double>(plot.series[k].name.size()) + 18.0;
    if (x > left && x + w > right) {
      x = left;
      ++row;
    }
    legend.push_back({k, x, row});
    x += w;
  }
  return legend;
}

/// The x axis over every series' x values ([0, 1] when there are none).
Axis MakeXAxis(const LinePlot& plot) {
  double x_lo = std::numeric_limits<double>::infinity();
  double x_hi = -x_lo;
  for (const LineSeries& s : plot.series) {
    for (double x : s.x) {
      x_lo = std::min(x_lo, x);
      x_hi = std::max(x_hi, x);
    }
  }
  if (x_lo > x_hi) {
    x_lo = 0.0;
    x_hi = 1.0;
  }
  return MakeAxis(x_lo, x_hi, false, false, plot.integer_x);
}

/// Where everything goes (px, y down): the plot area, its axes, the mapping of data to pixels and
/// the legend.
struct PlotLayout {
  double W = 0.0;  ///< image width
  double left = 0.0;
  double right = 0.0;
  double top = 0.0;
  double bottom = 0.0;
  bool has_right = false;  ///< a series uses the right axis
  Axis ax;
  Axis ay;
  Axis ay2;  ///< right axis (no ticks without has_right)
  std::vector<LegendEntry> legend;

  double px(double x) const { return left + (x - ax.lo) / (ax.hi - ax.lo) * (right - left); }
  double py(double y, bool r) const {
    const Axis& a = r ? ay2 : ay;
    return bottom - (y - a.lo) / (a.hi - a.lo) * (bottom - top);
  }
};

PlotLayout LayoutOf(const LinePlot& plot) {
  PlotLayout l;
  l.has_right = std::any_of(plot.series.begin(), plot.series.end(),
                            [](const LineSeries& s) { return s.right_axis; });
  l.W = plot.width_px;
  const double H = plot.height_px;
  l.left = kMarginLeft;
  l.right = l.W - (l.has_right ? kMarginRightAxis : kMarginRightPlain);
  l.legend = LegendLayout(plot, l.left, l.right);
  const int legend_rows = l.legend.empty() ? 0 : l.legend.back().row + 1;
  l.top = kMarginTop;
  l.bottom = std::max(l.top + 60.0, H - kAxisBelow - legend_rows * kLegendRow - 8.0);
  l.ax = MakeXAxis(plot);
  l.ay = MakeYAxis(plot, false);
  if (l.has_right) l.ay2 = MakeYAxis(plot, true);
  return l;
}

/// The XML declaration, the <svg> element, the title, the plot-area clip path and the background.
std::string SvgHeader(const LinePlot& plot, const PlotLayout& a) {
  std::string svg;
  svg += fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
      "viewBox=\"0 0 {0} {1}\" font-family=\"Helvetica, Arial, sans-serif\" font-size=\"12\">\n",
      plot.width_px, plot.height_px);
  if (!plot.title.empty()) svg += fmt::format("<title>{}</title>\n", EscapeXml(plot.title));
  svg += fmt::format(
      "<defs><clipPath id=\"plot-area\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/>"
      "</clipPath></defs>\n",
      Num(a.left), Num(a.top), Num(a.right - a.left), Num(a.bottom - a.top));
  svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  return svg;
}

/// Grid lines, the frame, tick marks and tick labels.
void AppendGridAndTicks(const PlotLayout& a, std::string& svg) {
  svg += "<g class=\"grid\" stroke=\"#e5e5e5\" stroke-width=\"1\">\n";
  for (double t : a.ax.ticks) {
    svg += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\"/>\n", Num(a.px(t)),
                       Num(a.top), Num(a.bottom));
  }
  for (double t : a.ay.ticks) {
    svg += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\"/>\n", Num(a.py(t, false)),
                       Num(a.left), Num(a.right));
  }
  svg += "</g>\n";
  svg += "<g class=\"axes\" stroke=\"#333333\" stroke-width=\"1\" fill=\"none\">\n";
  svg += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/>\n", Num(a.left),
                     Num(a.top), Num(a.right - a.left), Num(a.bottom - a.top));
  for (double t : a.ax.ticks) {
    svg += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\"/>\n", Num(a.px(t)),
                       Num(a.bottom), Num(a.bottom + 5.0));
  }
  for (double t : a.ay.ticks) {
    svg += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\"/>\n", Num(a.py(t, false)),
                       Num(a.left - 5.0), Num(a.left));
  }
  for (double t : a.ay2.ticks) {
    svg += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\"/>\n", Num(a.py(t, true)),
                       Num(a.right), Num(a.right + 5.0));
  }
  svg += "</g>\n";
  svg += "<g class=\"tick-labels\" fill=\"#333333\">\n";
  for (double t : a.ax.ticks) {
    svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", Num(a.px(t)),
                       Num(a.bottom + 19.0), TickLabel(t, a.ax.decimals));
  }
  for (double t : a.ay.ticks) {
    svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{}</text>\n", Num(a.left - 8.0),
                       Num(a.py(t, false) + 4.0), TickLabel(t, a.ay.decimals));
  }
  for (double t : a.ay2.ticks) {
    svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"start\">{}</text>\n",
                       Num(a.right + 8.0), Num(a.py(t, true) + 4.0), TickLabel(t, a.ay2.decimals));
  }
  svg += "</g>\n";
}

/// The title and the axis labels that are set (the right one only with a right axis).
void AppendTitleAndAxisLabels(const LinePlot& plot, const PlotLayout& a, std::string& svg) {
  if (!plot.title.empty()) {
    svg += fmt::format(
        "<text class=\"title\" x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"15\" "
        "font-weight=\"bold\">{}</text>\n",
        Num(0.5 * (a.left + a.right)), Num(a.top - 16.0), EscapeXml(plot.title));
  }
  if (!plot.x_label.empty()) {
    svg +=
        fmt::format("<text class=\"x-label\" x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n",
                    Num(0.5 * (a.left + a.right)), Num(a.bottom + 40.0), EscapeXml(plot.x_label));
  }
  if (!plot.y_label.empty()) {
    svg += fmt::format(
        "<text class=\"y-label\" transform=\"translate({},{}) rotate(-90)\" "
        "text-anchor=\"middle\">{}</text>\n",
        Num(18.0), Num(0.5 * (a.top + a.bottom)), EscapeXml(plot.y_label));
  }
  if (a.has_right && !plot.y2_label.empty()) {
    svg += fmt::format(
        "<text class=\"y2-label\" transform=\"translate({},{}) rotate(90)\" "
        "text-anchor=\"middle\">{}</text>\n",
        Num(a.W - 18.0), Num(0.5 * (a.top + a.bottom)), EscapeXml(plot.y2_label));
  }
}

/// Each series' colour: its own, or the next palette colour.
std::vector<std::string> SeriesColors(const LinePlot& plot) {
  std::vector<std::string> colors;
  size_t palette = 0;
  for (const LineSeries& s : plot.series) {
    colors.push_back(s.color.empty() ? std::string(kPalette[palette++ % kPalette.size()])
                                     : s.color);
  }
  return colors;
}

/// One polygon per run of finite values and bands: the upper ends forwards, the lower backwards.
void AppendSeriesBands(const LinePlot& plot, const PlotLayout& a,
                       const std::vector<std::string>& colors, std::string& svg) {
  for (size_t k = 0; k < plot.series.size(); ++k) {
    const LineSeries& s = plot.series[k];
    if (s.band_lo.empty()) continue;
    const auto ok = [&](size_t i) {
      return std::isfinite(s.y[i]) && std::isfinite(s.band_lo[i]) && std::isfinite(s.band_hi[i]);
    };
    for (const auto& [lo, hi] : Runs(s.y.size(), ok)) {
      std::string points;
      for (size_t i = lo; i <= hi; ++i) {
        points += fmt::format("{},{} ", Num(a.px(s.x[i])), Num(a.py(s.band_hi[i], s.right_axis)));
      }
      for (size_t i = hi + 1; i-- > lo;) {
        points += fmt::format("{},{} ", Num(a.px(s.x[i])), Num(a.py(s.band_lo[i], s.right_axis)));
      }
      points.pop_back();
      svg += fmt::format(
          "<polygon points=\"{}\" fill=\"{}\" fill-opacity=\"0.18\" stroke=\"none\"/>\n", points,
          colors[k]);
    }
  }
}

/// The stroke width of series `k`: each narrower than the one before (3.5, 2.5, 1.5 px, at least
/// 1.25), so that two series with equal values stay visible, the later one inside the earlier.
double StrokeWidth(size_t k) { return std::max(1.25, 3.5 - static_cast<double>(k)); }

/// One polyline per run of finite values (dashed on the right axis), with markers if asked for.
void AppendSeriesLines(const LinePlot& plot, const PlotLayout& a,
                       const std::vector<std::string>& colors, std::string& svg) {
  for (size_t k = 0; k < plot.series.size(); ++k) {
    const LineSeries& s = plot.series[k];
    const std::string dash = s.right_axis ? " stroke-dasharray=\"6 3\"" : "";
    const double width = StrokeWidth(k);
    const auto ok = [&](size_t i) { return std::isfinite(s.y[i]); };
    for (const auto& [lo, hi] : Runs(s.y.size(), ok)) {
      std::string points;
      for (size_t i = lo; i <= hi; ++i) {
        points += fmt::format("{},{} ", Num(a.px(s.x[i])), Num(a.py(s.y[i], s.right_axis)));
      }
      points.pop_back();
      svg += fmt::format(
          "<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"{}\"{}/>\n", points,
          colors[k], Num(width), dash);
      if (!s.markers) continue;
      for (size_t i = lo; i <= hi; ++i) {
        svg +=
            fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{}\"/>\n", Num(a.px(s.x[i])),
                        Num(a.py(s.y[i], s.right_axis)), Num(width * 0.5 + 1.5), colors[k]);
      }
    }
  }
}

/// The legend under the x label (nothing when no series is named).
void AppendLegend(const LinePlot& plot, const PlotLayout& a, const std::vector<std::string>& colors,
                  std::string& svg) {
  if (a.legend.empty()) return;
  svg += "<g class=\"legend\">\n";
  for (const LegendEntry& e : a.legend) {
    const LineSeries& s = plot.series[e.series];
    const double y = a.bottom + kAxisBelow + 4.0 + e.row * kLegendRow;
    if (!s.band_lo.empty()) {
      svg += fmt::format(
          "<rect x=\"{}\" y=\"{}\" width=\"26\" height=\"10\" fill=\"{}\" "
          "fill-opacity=\"0.18\"/>\n",
          Num(e.x), Num(y - 5.0), colors[e.series]);
    }
    svg += fmt::format(
        "<line x1=\"{0}\" y1=\"{2}\" x2=\"{1}\" y2=\"{2}\" stroke=\"{3}\" "
        "stroke-width=\"{5}\"{4}/>\n",
        Num(e.x), Num(e.x + 26.0), Num(y), colors[e.series],
        s.right_axis ? " stroke-dasharray=\"6 3\"" : "", Num(StrokeWidth(e.series)));
    svg += fmt::format("<text x=\"{}\" y=\"{}\" fill=\"#333333\">{}{}</text>\n", Num(e.x + 32.0),
                       Num(y + 4.0), EscapeXml(s.name), s.right_axis ? " (right)" : "");
  }
  svg += "</g>\n";
}

}  // namespace

std::string EscapeXml(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

Status LinePlot::Validate() const {
  std::vector<std::string> errors;
  if (width_px < 200 || width_px > 4000) {
    errors.push_back(fmt::format("width_px ({}) must be in [200, 4000]", width_px));
  }
  if (height_px < 200 || height_px > 4000) {
    errors.push_back(fmt::format("height_px ({}) must be in [200, 4000]", height_px));
  }
  const auto check_range = [&](double lo, double hi, std::string_view name) {
    if (std::isinf(lo) || std::isinf(hi)) {
      errors.push_back(
          fmt::format("{} range [{}, {}] must be finite or NaN (automatic)", name, lo, hi));
    } else if (std::isfinite(lo) && std::isfinite(hi) && !(lo < hi)) {
      errors.push_back(fmt::format("{} range [{}, {}] must have min < max", name, lo, hi));
    }
  };
  check_range(y_min, y_max, "y");
  check_range(y2_min, y2_max, "y2");
  for (size_t k = 0; k < series.size(); ++k) {
    const LineSeries& s = series[k];
    const std::string who = fmt::format("series {} ('{}')", k, s.name);
    if (s.x.size() != s.y.size()) {
      errors.push_back(fmt::format("{}: x has {} values, y {}", who, s.x.size(), s.y.size()));
    }
    if ((!s.band_lo.empty() || !s.band_hi.empty()) &&
        (s.band_lo.size() != s.y.size() || s.band_hi.size() != s.y.size())) {
      errors.push_back(fmt::format("{}: band_lo has {} values, band_hi {}, y {}", who,
                                   s.band_lo.size(), s.band_hi.size(), s.y.size()));
    }
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i])) {
        errors.push_back(fmt::format("{}: x[{}] ({}) must be finite", who, i, s.x[i]));
        break;
      }
    }
    for (size_t i = 0; i < std::min(s.band_lo.size(), s.band_hi.size()); ++i) {
      if (s.band_lo[i] > s.band_hi[i]) {
        errors.push_back(fmt::format("{}: band_lo[{}] ({}) must be <= band_hi[{}] ({})", who, i,
                                     s.band_lo[i], i, s.band_hi[i]));
        break;
      }
    }
    if (s.color.find_first_of("<>&\"'") != std::string::npos) {
      errors.push_back(fmt::format("{}: color ('{}') is not an SVG colour", who, s.color));
    }
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid line plot: {}", fmt::join(errors, "; ")));
}

Result<std::string> RenderLinePlotSvg(const LinePlot& plot) {
  AVP_RETURN_IF_ERROR(plot.Validate());
  const PlotLayout layout = LayoutOf(plot);
  const std::vector<std::string> colors = SeriesColors(plot);
  std::string svg = SvgHeader(plot, layout);
  AppendGridAndTicks(layout, svg);
  AppendTitleAndAxisLabels(plot, layout, svg);
  // Series: bands first (under every line), then lines and markers.
  svg += "<g class=\"series\" clip-path=\"url(#plot-area)\">\n";
  AppendSeriesBands(plot, layout, colors, svg);
  AppendSeriesLines(plot, layout, colors, svg);
  svg += "</g>\n";
  AppendLegend(plot, layout, colors, svg);
  svg += "</svg>\n";
  return svg;
}

Status WriteLinePlotSvg(const std::filesystem::path& path, const LinePlot& plot) {
  AVP_ASSIGN_OR_RETURN(const std::string svg, RenderLinePlotSvg(plot));
  return io::WriteFileAtomic(path, svg, "plot");
}

}  // namespace avp::report
