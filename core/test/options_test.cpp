#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/options.h>

namespace avp {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;

enum class Mode { kFast, kExact };

struct Inner {
  double radius_m = 0.25;
  std::vector<double> radii_m = {0.35, 0.55};
};

struct Example {
  double p = 0.05;
  float f = 0.9f;
  int count = 12;
  uint64_t seed = 0;
  bool enabled = true;
  std::string name = "tomato";
  Mode mode = Mode::kExact;
  Inner inner;
};

const OptionTable<Inner>& InnerTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<Inner>("inner option");
    t->Real("radius_m", &Inner::radius_m, "m", ValueRange::HalfOpen(0, 2), "a radius");
    t->RealList("radii_m", &Inner::radii_m, "m", ValueRange::Open(0.05, 3), 2, 2, "shell radii");
    t->AddRule([](const Inner& o, std::vector<std::string>& problems) {
      if (o.radii_m.size() == 2 && o.radii_m[0] > o.radii_m[1]) {
        problems.push_back("radii_m must be MIN,MAX");
      }
    });
    return t;
  }();
  return *table;
}

const OptionTable<Example>& ExampleTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<Example>("example option");
    t->Real("p", &Example::p, "", ValueRange::HalfOpen(0, 1), "a probability");
    t->Real("f", &Example::f, "", ValueRange::LeftOpen(0, 1), "a float");
    t->Integer("count", &Example::count, "", ValueRange::AtLeast(1), "a count");
    t->Integer("seed", &Example::seed, "", ValueRange::Any(), "a seed");
    t->Flag("enabled", &Example::enabled, "a flag");
    t->Text("name", &Example::name, "a name");
    t->Choice("mode", &Example::mode, {{Mode::kFast, "fast"}, {Mode::kExact, "exact"}}, "a mode");
    t->Nested("inner", &Example::inner, InnerTable());
    return t;
  }();
  return *table;
}

TEST(OptionHelpTest, ColumnsStayAlignedWhenOneDefaultIsLong) {
  std::vector<OptionInfo> info(3);
  const auto set = [](OptionInfo& i, std::string key, std::string unit, std::string range,
                      std::string doc, std::string default_value) {
    i.key = std::move(key);
    i.unit = std::move(unit);
    i.range = std::move(range);
    i.doc = std::move(doc);
    i.default_value = std::move(default_value);
  };
  set(info[0], "p", "m", "[0, 1]", "a probability", "0.5");
  set(info[1], "words", "", "", "many words", std::string(60, 'w'));
  set(info[2], "count", "", ">= 1", "a count", "3");
  const std::string help = FormatOptionHelp(info, "  ");
  std::vector<std::string> lines;
  for (size_t pos = 0, end; (end = help.find('\n', pos)) != std::string::npos; pos = end + 1) {
    lines.push_back(help.substr(pos, end - pos));
  }
  ASSERT_EQ(lines.size(), 4u) << help;  // the long default alone on its line
  EXPECT_EQ(lines[1], "  words=" + std::string(60, 'w'));
  // Every meaning starts in the same column, however long the long default is.
  const size_t column = lines[0].find("a probability");
  EXPECT_EQ(lines[2].find("many words"), column) << help;
  EXPECT_EQ(lines[3].find("a count"), column) << help;
  EXPECT_LT(column, 40u);
}

TEST(ValueRangeTest, ContainsAndPrints) {
  EXPECT_TRUE(ValueRange::HalfOpen(0, 1).Contains(0.0));
  EXPECT_FALSE(ValueRange::HalfOpen(0, 1).Contains(1.0));
  EXPECT_FALSE(ValueRange::Above(0).Contains(0.0));
  EXPECT_TRUE(ValueRange::Above(0).Contains(1e-9));
  EXPECT_FALSE(ValueRange::Closed(0, 1).Contains(std::numeric_limits<double>::quiet_NaN()));
  EXPECT_EQ(ValueRange::HalfOpen(0, 1).ToString(), "[0, 1)");
  EXPECT_EQ(ValueRange::Closed(0.002, 0.02).ToString(), "[0.002, 0.02]");
  EXPECT_EQ(ValueRange::AtLeast(1).ToString(), ">= 1");
  EXPECT_EQ(ValueRange::Above(0).Requirement(), "> 0");
  EXPECT_EQ(ValueRange::Open(0, 1).Requirement(), "in (0, 1)");
  EXPECT_EQ(ValueRange::Any().ToString(), "");
}

TEST(OptionTableTest, ValuesRoundTripThroughText) {
  Example e;
  e.p = 0.1;
  e.f = 0.3f;
  e.count = 7;
  e.seed = 18446744073709551615ull;
  e.enabled = false;
  e.name = "green apple";
  e.mode = Mode::kFast;
  e.inner.radius_m = 1.0 / 3.0;
  e.inner.radii_m = {0.3, 0.7};
  const OptionValues values = ExampleTable().Values(e);
  Example back;
  ASSERT_TRUE(ExampleTable().SetAll(back, values).ok());
  EXPECT_EQ(back.p, e.p);
  EXPECT_EQ(back.f, e.f);
  EXPECT_EQ(back.count, 7);
  EXPECT_EQ(back.seed, e.seed);
  EXPECT_FALSE(back.enabled);
  EXPECT_EQ(back.name, "green apple");
  EXPECT_EQ(back.mode, Mode::kFast);
  EXPECT_EQ(back.inner.radius_m, 1.0 / 3.0);  // bit-exact: shortest round-trip text
  EXPECT_EQ(back.inner.radii_m, e.inner.radii_m);
  EXPECT_TRUE(ExampleTable().Differences(back, e).empty());
}

TEST(OptionTableTest, KeysAndDefaultsInTableOrder) {
  EXPECT_THAT(ExampleTable().Keys(), ElementsAre("p", "f", "count", "seed", "enabled", "name",
                                                 "mode", "inner.radius_m", "inner.radii_m"));
  const std::vector<OptionInfo> info = ExampleTable().Info();
  ASSERT_EQ(info.size(), 9u);
  EXPECT_EQ(info[0].default_value, "0.05");
  EXPECT_EQ(info[1].default_value, "0.9");
  EXPECT_EQ(info[6].default_value, "exact");
  EXPECT_THAT(info[6].choices, ElementsAre("fast", "exact"));
  EXPECT_EQ(info[8].default_value, "0.35,0.55");
  EXPECT_EQ(info[8].unit, "m");
  EXPECT_EQ(info[7].range, "[0, 2)");
}

TEST(OptionTableTest, SetNamesUnknownKeysAndBadValues) {
  Example e;
  Status s = ExampleTable().Set(e, "nope", "1");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("unknown example option 'nope' (known: p, f, count"));
  s = ExampleTable().Set(e, "count", "2.5");
  EXPECT_EQ(s.message(), "example option count: '2.5' is not a whole number");
  EXPECT_TRUE(ExampleTable().Set(e, "count", "1e3").ok());
  EXPECT_EQ(e.count, 1000);
  s = ExampleTable().Set(e, "seed", "-1");  // never wraps to 2^64 - 1
  EXPECT_EQ(s.message(), "example option seed: '-1' is not a whole number >= 0");
  s = ExampleTable().Set(e, "p", "nan");
  EXPECT_THAT(s.message(), HasSubstr("is not a finite number"));
  s = ExampleTable().Set(e, "enabled", "yes");
  EXPECT_THAT(s.message(), HasSubstr("is not true or false"));
  s = ExampleTable().Set(e, "mode", "slow");
  EXPECT_EQ(s.message(), "example option mode: 'slow' is not one of fast, exact");
  s = ExampleTable().Set(e, "inner.radii_m", "0.3,x");
  EXPECT_THAT(s.message(), HasSubstr("a comma-separated list of finite numbers"));
  EXPECT_EQ(e.inner.radii_m, (std::vector<double>{0.35, 0.55}));  // unchanged on error
  EXPECT_EQ(ExampleTable().Get(e, "inner.radius_m"), "0.25");
  EXPECT_FALSE(ExampleTable().Get(e, "radius_m").has_value());
}

TEST(OptionTableTest, ValidateNamesEveryBadField) {
  Example e;
  EXPECT_TRUE(ExampleTable().Validate(e).ok());
  e.p = 1.0;
  e.count = 0;
  e.f = std::numeric_limits<float>::infinity();
  e.inner.radius_m = -1;
  e.inner.radii_m = {0.6, 0.4};
  const Status s = ExampleTable().Validate(e);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(),
            "invalid example options: p (1) must be in [0, 1); f (inf) must be finite; count (0) "
            "must be >= 1; inner.radius_m (-1 m) must be in [0, 2); inner.radii_m must be MIN,MAX");
  e = Example{};
  e.inner.radii_m = {0.01};
  EXPECT_EQ(ExampleTable().Validate(e).message(),
            "invalid example options: inner.radii_m has 1 values, must have 2 values; "
            "inner.radii_m[0] (0.01 m) must be in (0.05, 3)");
}

TEST(AnyOptionsTest, HoldsAnyTableAndChecksItsType) {
  Example defaults;
  defaults.count = 3;
  AnyOptions any(ExampleTable(), defaults);
  EXPECT_TRUE(any.has_fields());
  EXPECT_EQ(any.As<Example>().count, 3);
  ASSERT_TRUE(any.Set("p", "0.25").ok());
  AnyOptions copy = any;
  ASSERT_TRUE(copy.Set("p", "0.5").ok());
  EXPECT_EQ(any.As<Example>().p, 0.25);
  EXPECT_EQ(copy.As<Example>().p, 0.5);
  EXPECT_EQ(any.Info()[2].default_value, "3");  // the held value's defaults
  EXPECT_THROW((void)any.As<Inner>(), Error);
  AnyOptions none;
  EXPECT_FALSE(none.has_fields());
  EXPECT_TRUE(none.Validate().ok());
  EXPECT_EQ(none.Set("p", "1", "planner 'predefined'").message(),
            "planner 'predefined' has no options (given: p = 1)");
}

TEST(ParseKeyValuesTest, SplitsAtTheFirstEquals) {
  const Result<OptionValues> v = ParseKeyValues({"a=1", "b.c=x=y", "d="}, "planner option");
  ASSERT_TRUE(v.ok());
  EXPECT_THAT(*v, ElementsAre(Pair("a", "1"), Pair("b.c", "x=y"), Pair("d", "")));
  EXPECT_EQ(ParseKeyValues({"=1"}, "planner option").status().message(),
            "planner option '=1' must be KEY=VALUE");
  EXPECT_FALSE(ParseKeyValues({"novalue"}, "map option").ok());
}

}  // namespace
}  // namespace avp
