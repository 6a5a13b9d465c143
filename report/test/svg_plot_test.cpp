// The SVG line-chart writer: a well-formed document with the series, labels and legend as text,
// escaping, bands, gaps, a second axis, validation errors and the atomic write.
#include <cctype>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/report/svg_plot.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// A small XML well-formedness check: one root element, balanced and properly nested tags,
/// quoted attributes, only the five predefined entities (or numeric ones) in text and attributes,
/// no stray '<' or '&'. Returns an empty string when well formed, else what is wrong and where.
std::string XmlProblem(const std::string& xml) {
  std::vector<std::string> open;
  size_t i = 0;
  int roots = 0;
  const auto entity_ok = [&](size_t at) {
    const size_t semi = xml.find(';', at);
    if (semi == std::string::npos || semi - at > 8) return false;
    const std::string name = xml.substr(at + 1, semi - at - 1);
    if (name == "amp" || name == "lt" || name == "gt" || name == "quot" || name == "apos") {
      return true;
    }
    return name.size() > 1 && name[0] == '#';
  };
  while (i < xml.size()) {
    const char c = xml[i];
    if (c == '&') {
      if (!entity_ok(i)) return "bad entity at " + std::to_string(i);
      ++i;
      continue;
    }
    if (c == '>') return "stray '>' at " + std::to_string(i);
    if (c != '<') {
      if (open.empty() && !std::isspace(static_cast<unsigned char>(c))) {
        return "text outside the root at " + std::to_string(i);
      }
      ++i;
      continue;
    }
    if (xml.compare(i, 5, "<?xml") == 0) {
      const size_t end = xml.find("?>", i);
      if (end == std::string::npos || i != 0) return "bad XML declaration";
      i = end + 2;
      continue;
    }
    const bool closing = i + 1 < xml.size() && xml[i + 1] == '/';
    size_t j = i + (closing ? 2 : 1);
    const size_t name_start = j;
    while (j < xml.size() && (std::isalnum(static_cast<unsigned char>(xml[j])) || xml[j] == '-' ||
                              xml[j] == ':' || xml[j] == '_')) {
      ++j;
    }
    const std::string name = xml.substr(name_start, j - name_start);
    if (name.empty()) return "empty tag name at " + std::to_string(i);
    if (closing) {
      if (j >= xml.size() || xml[j] != '>') return "bad closing tag " + name;
      if (open.empty() || open.back() != name) return "mismatched </" + name + ">";
      open.pop_back();
      i = j + 1;
      continue;
    }
    // Attributes: name="value" pairs.
    bool self_closing = false;
    while (true) {
      while (j < xml.size() && std::isspace(static_cast<unsigned char>(xml[j]))) ++j;
      if (j >= xml.size()) return "unterminated tag " + name;
      if (xml[j] == '>') break;
      if (xml.compare(j, 2, "/>") == 0) {
        self_closing = true;
        ++j;
        break;
      }
      const size_t attr_start = j;
      while (j < xml.size() && xml[j] != '=' && !std::isspace(static_cast<unsigned char>(xml[j])) &&
             xml[j] != '>') {
        ++j;
      }
      if (j == attr_start || j >= xml.size() || xml[j] != '=') {
        return "bad attribute in <" + name + "> at " + std::to_string(j);
      }
      ++j;
      if (j >= xml.size() || xml[j] != '"') return "unquoted attribute in <" + name + ">";
      const size_t value_end = xml.find('"', j + 1);
      if (value_end == std::string::npos) return "unterminated attribute in <" + name + ">";
      for (size_t k = j + 1; k < value_end; ++k) {
        if (xml[k] == '<') return "'<' in an attribute of <" + name + ">";
        if (xml[k] == '&' && !entity_ok(k)) return "bad entity in an attribute of <" + name + ">";
      }
      j = value_end + 1;
    }
    if (open.empty()) ++roots;
    if (roots > 1) return "more than one root element";
    if (!self_closing) open.push_back(name);
    i = j + 1;
  }
  if (!open.empty()) return "unclosed <" + open.back() + ">";
  if (roots != 1) return "no root element";
  return "";
}

std::string ReadFile(const fs::path& path) { return test::ReadWholeFile(path); }

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

LinePlot Fig3Like() {
  LinePlot plot;
  plot.title = "tomato-single-cluster: F1 & fruits found per view";
  plot.y_label = "F1";
  plot.y2_label = "fruits found";
  plot.y_min = 0.0;
  plot.y_max = 1.0;
  LineSeries a;
  a.name = "avp-nbv <ours>";
  a.x = {1, 2, 3, 4, 5, 6, 7, 8};
  a.y = {0.20, 0.35, 0.48, 0.55, 0.61, 0.64, 0.66, 0.67};
  for (size_t i = 0; i < a.y.size(); ++i) {
    const double half = i == 3 ? 0.04 : i == 1 || i == 2 || i == 4 ? 0.03 : 0.02;
    a.band_lo.push_back(a.y[i] - half);
    a.band_hi.push_back(a.y[i] + half);
  }
  LineSeries b;
  b.name = "predefined";
  b.x = a.x;
  b.y = {0.20, 0.28, 0.37, kNaN, 0.50, 0.55, 0.58, 0.60};
  LineSeries c;
  c.name = "fruits found (avp-nbv)";
  c.x = a.x;
  c.y = {2, 3, 4, 5, 5, 6, 6, 6};
  c.right_axis = true;
  plot.series = {a, b, c};
  return plot;
}

class SvgPlotFileTest : public avp::test::TempDirTest {};

TEST_F(SvgPlotFileTest, WritesWellFormedSvgWithSeriesNames) {
  const fs::path path = dir_ / "sub" / "f1.svg";
  ASSERT_TRUE(WriteLinePlotSvg(path, Fig3Like()).ok());
  ASSERT_TRUE(fs::exists(path));
  EXPECT_FALSE(fs::exists(dir_ / "sub" / "f1.svg.tmp"));
  const std::string svg = ReadFile(path);
  EXPECT_EQ(XmlProblem(svg), "") << svg;
  EXPECT_THAT(svg, HasSubstr("<svg xmlns=\"http://www.w3.org/2000/svg\""));
  // Text is escaped, names appear in the legend.
  EXPECT_THAT(svg, HasSubstr("avp-nbv &lt;ours&gt;"));
  EXPECT_THAT(svg, Not(HasSubstr("<ours>")));
  EXPECT_THAT(svg, HasSubstr(">predefined</text>"));
  EXPECT_THAT(svg, HasSubstr(">fruits found (avp-nbv) (right)</text>"));
  EXPECT_THAT(svg, HasSubstr("F1 &amp; fruits found per view"));
  EXPECT_THAT(svg, HasSubstr(">view</text>"));
  EXPECT_THAT(svg, HasSubstr(">F1</text>"));
  EXPECT_THAT(svg, HasSubstr(">fruits found</text>"));
  // Integer view ticks 1..8, F1 ticks 0.0..1.0.
  for (int v = 1; v <= 8; ++v) {
    EXPECT_THAT(svg, HasSubstr("text-anchor=\"middle\">" + std::to_string(v) + "</text>"));
  }
  EXPECT_THAT(svg, Not(HasSubstr(">1.5</text>")));
  EXPECT_THAT(svg, HasSubstr("text-anchor=\"end\">0.0</text>"));
  EXPECT_THAT(svg, HasSubstr("text-anchor=\"end\">1.0</text>"));
  // One band (series a), four polylines: a, b split by its NaN into two, c (dashed).
  EXPECT_EQ(Count(svg, "<polygon "), 1u);
  EXPECT_EQ(Count(svg, "<polyline "), 4u);
  EXPECT_EQ(Count(svg, "stroke-dasharray"), 2u);  // c's line and its legend sample
  EXPECT_EQ(Count(svg, "<circle "), 8u + 7u + 8u);
  // Default palette colours, in order.
  EXPECT_THAT(svg, HasSubstr("#1f77b4"));
  EXPECT_THAT(svg, HasSubstr("#ff7f0e"));
  EXPECT_THAT(svg, HasSubstr("#2ca02c"));
}

TEST(SvgPlotTest, RendersEmptyAndSinglePointPlots) {
  LinePlot plot;
  plot.title = "empty";
  const Result<std::string> empty = RenderLinePlotSvg(plot);
  ASSERT_TRUE(empty.ok()) << empty.status().ToString();
  EXPECT_EQ(XmlProblem(*empty), "");
  EXPECT_THAT(*empty, Not(HasSubstr("<polyline")));

  LineSeries one;
  one.name = "one";
  one.x = {3};
  one.y = {0.5};
  one.color = "red";
  plot.series = {one};
  const Result<std::string> single = RenderLinePlotSvg(plot);
  ASSERT_TRUE(single.ok());
  EXPECT_EQ(XmlProblem(*single), "");
  EXPECT_EQ(Count(*single, "<circle "), 1u);
  EXPECT_THAT(*single, HasSubstr("stroke=\"red\""));
  EXPECT_THAT(*single, Not(HasSubstr("nan")));
  EXPECT_THAT(*single, Not(HasSubstr("inf")));
}

TEST(SvgPlotTest, EscapesEveryMarkupCharacter) {
  EXPECT_EQ(EscapeXml("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&apos;");
  EXPECT_EQ(EscapeXml("plain"), "plain");
}

TEST_F(SvgPlotFileTest, RejectsBadPlotsNamingTheValue) {
  LinePlot plot = Fig3Like();
  plot.series[1].y.pop_back();
  plot.series[0].band_lo[2] = plot.series[0].band_hi[2] + 0.1;
  plot.width_px = 50;
  const Status s = WriteLinePlotSvg(dir_ / "never.svg", plot);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("series 1 ('predefined'): x has 8 values, y 7"));
  EXPECT_THAT(s.message(), HasSubstr("band_lo[2] ("));
  EXPECT_THAT(s.message(), HasSubstr("width_px (50)"));
  EXPECT_FALSE(fs::exists(dir_ / "never.svg"));

  LinePlot range = Fig3Like();
  range.y_min = 1.0;
  range.y_max = 0.0;
  EXPECT_THAT(range.Validate().message(), HasSubstr("y range [1, 0] must have min < max"));
  LinePlot x_nan = Fig3Like();
  x_nan.series[0].x[0] = kNaN;
  EXPECT_THAT(x_nan.Validate().message(), HasSubstr("x[0] (nan) must be finite"));
}

TEST_F(SvgPlotFileTest, WriteFailsOnUnwritablePath) {
  const fs::path blocker = Write("file", "x");  // a file where a folder should be
  const Status s = WriteLinePlotSvg(blocker / "plot.svg", Fig3Like());
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr(blocker.string()));
}

}  // namespace
}  // namespace avp::report
