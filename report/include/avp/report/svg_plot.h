#pragma once

#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::report {

/// One line of a LinePlot.
struct LineSeries {
  /// Shown in the legend (escaped); an empty name leaves the series out of the legend.
  std::string name;
  /// Points; x finite, a non-finite y breaks the line there.
  std::vector<double> x;
  std::vector<double> y;
  /// Optional interval per point, its lower and upper ends (e.g. eval::Summary's ci_lo and
  /// ci_hi), drawn as a translucent band; both empty = none, else both as long as y; a non-finite
  /// entry leaves a gap. band_lo[i] <= band_hi[i].
  std::vector<double> band_lo, band_hi;
  /// SVG colour ("#1f77b4", "red"); empty = the next colour of the built-in palette.
  std::string color;
  /// Plotted against the right-hand y axis (LinePlot::y2_label), drawn dashed.
  bool right_axis = false;
  /// A dot at each point.
  bool markers = true;
};

/// A line chart in the style of the paper's Fig. 3 ("F1 and fruits found per view"): title, axis
/// labels, ticks, grid, legend below the axes, one or two y axes.
struct LinePlot {
  std::string title;
  std::string x_label = "view";
  std::string y_label;
  /// Label of the right-hand axis (used when a series has right_axis set).
  std::string y2_label;
  std::vector<LineSeries> series;
  /// Axis ranges; NaN = from the data (bands included), widened to whole ticks.
  double y_min = std::numeric_limits<double>::quiet_NaN();
  double y_max = std::numeric_limits<double>::quiet_NaN();
  double y2_min = std::numeric_limits<double>::quiet_NaN();
  double y2_max = std::numeric_limits<double>::quiet_NaN();
  /// x ticks at integers only (views).
  bool integer_x = true;
  /// Size of the drawing in pixels, each in [200, 4000].
  int width_px = 720;
  int height_px = 420;

  /// OK, or InvalidArgument naming every bad field (series by index and name) and its value.
  Status Validate() const;
};

/// The SVG document of `plot`. Errors: those of LinePlot::Validate.
Result<std::string> RenderLinePlotSvg(const LinePlot& plot);

/// Writes RenderLinePlotSvg(plot) to `path` atomically (a temporary file beside it, then a
/// rename), creating parent folders. Errors: InvalidArgument (bad plot), IoError naming the path.
Status WriteLinePlotSvg(const std::filesystem::path& path, const LinePlot& plot);

/// `text` with &, <, >, " and ' replaced by XML entities.
std::string EscapeXml(std::string_view text);

}  // namespace avp::report
