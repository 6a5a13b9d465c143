#pragma once

// One field table per options struct (docs/extending.md, "Options"): each field's name, unit,
// valid range and one-line doc, written once next to the struct. The table drives Validate(),
// text and YAML reading and writing (io/options_yaml.h), the command line's KEY=VALUE options and
// the map-file header. The defaults are the struct's in-class initialisers: a table never repeats
// them, it reads them from a default-constructed value.

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <typeinfo>
#include <utility>
#include <vector>

#include <avp/core/error.h>
#include <avp/core/status.h>
#include <avp/core/text.h>

namespace avp {

/// The valid values of a numeric field: an interval, each end open or closed or absent.
struct ValueRange {
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false;
  bool hi_open = false;

  static ValueRange Any() { return {}; }
  static ValueRange AtLeast(double lo) { return {lo, kInf, false, false}; }  ///< [lo, inf)
  static ValueRange Above(double lo) { return {lo, kInf, true, false}; }     ///< (lo, inf)
  static ValueRange Closed(double lo, double hi) { return {lo, hi, false, false}; }
  static ValueRange HalfOpen(double lo, double hi) { return {lo, hi, false, true}; }  ///< [lo, hi)
  static ValueRange LeftOpen(double lo, double hi) { return {lo, hi, true, false}; }  ///< (lo, hi]
  static ValueRange Open(double lo, double hi) { return {lo, hi, true, true}; }

  bool Contains(double v) const;
  /// "[0.002, 0.02]", "[0, 1)", ">= 0", "> 0", or "" when any value is valid.
  std::string ToString() const;
  /// What a value must be: "in [0, 1)", ">= 0", "> 0" (after "must be").
  std::string Requirement() const;

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
};

/// What a field holds, for help texts and YAML (lists are written as sequences).
enum class OptionKind { kReal, kInteger, kFlag, kText, kChoice, kRealList, kTextList };

/// One field as help texts and docs show it.
struct OptionInfo {
  std::string key;  ///< "p_unknown", "candidates.radii_m"
  OptionKind kind = OptionKind::kReal;
  std::string unit;                  ///< "m", "deg", "px", "bits", or ""
  std::string range;                 ///< ValueRange::ToString, the choices, or a list's size
  std::string doc;                   ///< one line
  std::string default_value;         ///< as text (OptionTable::Get of the defaults)
  std::vector<std::string> choices;  ///< kChoice: the accepted names
};

/// One key and its value as text, in table order.
using OptionValues = std::vector<std::pair<std::string, std::string>>;

namespace options_internal {
// Text forms shared by every table: shortest round-trip numbers, "true"/"false", "a,b,c".
std::string FormatReal(double v);
std::string FormatFloat(float v);
std::optional<double> ParseReal(std::string_view text);
std::optional<int64_t> ParseInteger(std::string_view text);
std::optional<uint64_t> ParseUnsigned(std::string_view text);
std::optional<bool> ParseFlag(std::string_view text);
std::vector<std::string> SplitList(std::string_view text);
std::string Join(const std::vector<std::string>& items, std::string_view separator);
}  // namespace options_internal

/// The field table of options struct T. Build it once (a function-local static) and share it:
///   const OptionTable<IntegratorOptions>& IntegratorOptionTable() {
///     static const auto* table = [] {
///       auto* t = new OptionTable<IntegratorOptions>("integrator option");
///       t->Real("max_range_m", &IntegratorOptions::max_range_m, "m", ValueRange::LeftOpen(0, 100),
///               "returns beyond this carve free space only");
///       return t;
///     }();
///     return *table;
///   }
/// Keys are the struct's field names; a nested struct's keys get its prefix ("candidates.").
template <typename T>
class OptionTable {
 public:
  /// Adds the error for a value that breaks a rule spanning several fields.
  using Rule = std::function<void(const T&, std::vector<std::string>& problems)>;

  /// `noun` names one field in messages: "avp-nbv option" gives "unknown avp-nbv option 'x'"
  /// and "invalid avp-nbv options: ...".
  explicit OptionTable(std::string noun) : noun_(std::move(noun)) {}

  const std::string& noun() const { return noun_; }

  OptionTable& Real(std::string key, double T::*field, std::string unit, ValueRange range,
                    std::string doc) {
    return AddNumber<double>(std::move(key), field, std::move(unit), range, std::move(doc),
                             OptionKind::kReal);
  }
  OptionTable& Real(std::string key, float T::*field, std::string unit, ValueRange range,
                    std::string doc) {
    return AddNumber<float>(std::move(key), field, std::move(unit), range, std::move(doc),
                            OptionKind::kReal);
  }
  OptionTable& Integer(std::string key, int T::*field, std::string unit, ValueRange range,
                       std::string doc) {
    return AddNumber<int>(std::move(key), field, std::move(unit), range, std::move(doc),
                          OptionKind::kInteger);
  }
  OptionTable& Integer(std::string key, uint64_t T::*field, std::string unit, ValueRange range,
                       std::string doc) {
    return AddNumber<uint64_t>(std::move(key), field, std::move(unit), range, std::move(doc),
                               OptionKind::kInteger);
  }
  OptionTable& Flag(std::string key, bool T::*field, std::string doc);
  OptionTable& Text(std::string key, std::string T::*field, std::string doc);
  OptionTable& Path(std::string key, std::filesystem::path T::*field, std::string doc);
  /// A list of words ("tomato,apple"); entries may not contain commas.
  OptionTable& TextList(std::string key, std::vector<std::string> T::*field, std::string doc);
  /// An enum by name: `names` lists every accepted value and its name.
  template <typename E>
  OptionTable& Choice(std::string key, E T::*field, std::vector<std::pair<E, std::string>> names,
                      std::string doc);
  /// A list of reals, each in `each`, with min_size to max_size entries ("0.35,0.55").
  OptionTable& RealList(std::string key, std::vector<double> T::*field, std::string unit,
                        ValueRange each, size_t min_size, size_t max_size, std::string doc);
  /// Every field and rule of `sub` (a table of U), under "<prefix>." keys.
  template <typename U>
  OptionTable& Nested(const std::string& prefix, U T::*field, const OptionTable<U>& sub);
  /// A check spanning fields, run by Problems() after the per-field ones.
  OptionTable& AddRule(Rule rule) {
    rules_.push_back(std::move(rule));
    return *this;
  }

  /// The keys, in table order.
  std::vector<std::string> Keys() const;
  bool Has(std::string_view key) const { return Find(key) != nullptr; }
  /// Every field with its default (from T{}), in table order.
  std::vector<OptionInfo> Info() const { return Info(T{}); }
  /// The same, with the defaults taken from `defaults`.
  std::vector<OptionInfo> Info(const T& defaults) const;

  /// Sets one field from text. InvalidArgument naming the key and the known keys ("unknown
  /// avp-nbv option 'x' (known: ...)"), or the value and what it must be ("avp-nbv option
  /// ray_stride_px: 'abc' is not a whole number"). Ranges are checked by Validate, not here.
  Status Set(T& options, std::string_view key, std::string_view value) const;
  /// Applies KEY=VALUE pairs in order; the first error.
  Status SetAll(T& options, const OptionValues& values) const;
  /// The value of `key` as text; nullopt for an unknown key.
  std::optional<std::string> Get(const T& options, std::string_view key) const;
  /// Every field's value as text, in table order: Set(Values(o)) on T{} gives o back.
  OptionValues Values(const T& options) const;
  /// The fields whose value differs from `base`'s, in table order.
  OptionValues Differences(const T& options, const T& base) const;

  /// Every out-of-range value and broken rule, each naming the field and its value:
  /// "p_unknown (1.5) must be in [0, 1)".
  std::vector<std::string> Problems(const T& options) const;
  /// OK, or InvalidArgument "invalid <noun>s: <every problem>".
  Status Validate(const T& options) const;

 private:
  struct Field {
    OptionInfo info;  // default_value filled by Info()
    std::function<std::string(const T&)> get;
    /// Empty string: done; otherwise what the text must be ("a finite number").
    std::function<std::string(T&, std::string_view)> set;
    /// Appends the field's problem, if any.
    std::function<void(const T&, std::vector<std::string>&)> check;
  };
  template <typename>
  friend class OptionTable;

  template <typename N>
  OptionTable& AddNumber(std::string key, N T::*field, std::string unit, ValueRange range,
                         std::string doc, OptionKind kind);
  OptionTable& Add(Field field);
  const Field* Find(std::string_view key) const;

  std::string noun_;
  std::vector<Field> fields_;
  std::vector<Rule> rules_;
};

/// An options value of any table's type with its table: what a registry hands out for a named
/// component (a planner's, a segmenter's options), so a command line or a config file can set
/// them by key without knowing their type. Copyable; a default-constructed one has no fields
/// (a component without options).
class AnyOptions {
 public:
  AnyOptions() = default;
  /// `table` must outlive this value (tables are function-local statics).
  template <typename T>
  AnyOptions(const OptionTable<T>& table, T value);
  AnyOptions(const AnyOptions& other) : impl_(other.impl_ ? other.impl_->Clone() : nullptr) {}
  AnyOptions& operator=(const AnyOptions& other) {
    if (this != &other) impl_ = other.impl_ ? other.impl_->Clone() : nullptr;
    return *this;
  }
  AnyOptions(AnyOptions&&) noexcept = default;
  AnyOptions& operator=(AnyOptions&&) noexcept = default;

  /// False for a component without options.
  bool has_fields() const { return impl_ != nullptr && !impl_->Keys().empty(); }
  std::vector<std::string> Keys() const {
    return impl_ ? impl_->Keys() : std::vector<std::string>{};
  }
  std::vector<OptionInfo> Info() const { return impl_ ? impl_->Info() : std::vector<OptionInfo>{}; }
  OptionValues Values() const { return impl_ ? impl_->Values() : OptionValues{}; }
  /// As OptionTable::Set; `component` names the owner in the message of a component without
  /// options ("planner 'predefined' has no options (given: p_unknown)").
  Status Set(std::string_view key, std::string_view value, std::string_view component = {});
  Status SetAll(const OptionValues& values, std::string_view component = {});
  Status Validate() const { return impl_ ? impl_->Validate() : Status::Ok(); }

  /// The value. @throws avp::Error when T is not the held type (a bug in a factory).
  template <typename T>
  const T& As() const;
  /// True when the held value is a T.
  template <typename T>
  bool Holds() const {
    return impl_ != nullptr && impl_->type() == typeid(T);
  }

 private:
  struct Concept {
    virtual ~Concept() = default;
    virtual std::unique_ptr<Concept> Clone() const = 0;
    virtual std::vector<std::string> Keys() const = 0;
    virtual std::vector<OptionInfo> Info() const = 0;
    virtual OptionValues Values() const = 0;
    virtual Status Set(std::string_view key, std::string_view value) = 0;
    virtual Status Validate() const = 0;
    virtual const std::type_info& type() const = 0;
    virtual const void* value() const = 0;
  };
  template <typename T>
  struct Model final : Concept {
    Model(const OptionTable<T>* t, T v) : table(t), value_(std::move(v)) {}
    std::unique_ptr<Concept> Clone() const override { return std::make_unique<Model>(*this); }
    std::vector<std::string> Keys() const override { return table->Keys(); }
    std::vector<OptionInfo> Info() const override { return table->Info(value_); }
    OptionValues Values() const override { return table->Values(value_); }
    Status Set(std::string_view key, std::string_view value) override {
      return table->Set(value_, key, value);
    }
    Status Validate() const override { return table->Validate(value_); }
    const std::type_info& type() const override { return typeid(T); }
    const void* value() const override { return &value_; }
    const OptionTable<T>* table;
    T value_;
  };
  std::unique_ptr<Concept> impl_;
};

/// One line per field for help texts: "  KEY  VALUE-DEFAULT  [unit, range]  doc".
std::string FormatOptionHelp(const std::vector<OptionInfo>& info, std::string_view indent = "  ");

/// Splits "KEY=VALUE" items (command-line options) into pairs, in order; InvalidArgument naming
/// an item without '=' or with an empty key ("<what> 'x' must be KEY=VALUE").
Result<OptionValues> ParseKeyValues(const std::vector<std::string>& items, std::string_view what);

// ---- Implementation
// ------------------------------------------------------------------------------

template <typename T>
template <typename N>
OptionTable<T>& OptionTable<T>::AddNumber(std::string key, N T::*field, std::string unit,
                                          ValueRange range, std::string doc, OptionKind kind) {
  using namespace options_internal;
  Field f;
  f.info = {key, kind, unit, range.ToString(), std::move(doc), {}, {}};
  f.get = [field](const T& o) -> std::string {
    if constexpr (std::is_same_v<N, double>) {
      return FormatReal(o.*field);
    } else if constexpr (std::is_same_v<N, float>) {
      return FormatFloat(o.*field);
    } else {
      return std::to_string(o.*field);
    }
  };
  f.set = [field](T& o, std::string_view text) -> std::string {
    if constexpr (std::is_floating_point_v<N>) {
      const std::optional<double> v = ParseReal(text);
      if (!v) return "a finite number";
      o.*field = static_cast<N>(*v);
    } else if constexpr (std::is_signed_v<N>) {
      const std::optional<int64_t> v = ParseInteger(text);
      if (!v || *v < std::numeric_limits<N>::min() || *v > std::numeric_limits<N>::max()) {
        return "a whole number";
      }
      o.*field = static_cast<N>(*v);
    } else {
      const std::optional<uint64_t> v = ParseUnsigned(text);
      if (!v || *v > std::numeric_limits<N>::max()) return "a whole number >= 0";
      o.*field = static_cast<N>(*v);
    }
    return {};
  };
  f.check = [field, key, unit, range](const T& o, std::vector<std::string>& problems) {
    const double v = static_cast<double>(o.*field);
    const bool finite = !std::is_floating_point_v<N> || std::isfinite(v);
    if (finite && range.Contains(v)) return;
    const std::string value = std::is_same_v<N, float> ? FormatFloat(static_cast<float>(o.*field))
                              : std::is_floating_point_v<N> ? FormatReal(v)
                                                            : std::to_string(o.*field);
    const std::string shown = unit.empty() || !finite ? value : value + " " + unit;
    problems.push_back(key + " (" + shown + ") must be " +
                       (finite ? range.Requirement() : "finite"));
  };
  return Add(std::move(f));
}

template <typename T>
OptionTable<T>& OptionTable<T>::Flag(std::string key, bool T::*field, std::string doc) {
  Field f;
  f.info = {std::move(key), OptionKind::kFlag, "", "true or false", std::move(doc), {}, {}};
  f.get = [field](const T& o) -> std::string { return o.*field ? "true" : "false"; };
  f.set = [field](T& o, std::string_view text) -> std::string {
    const std::optional<bool> v = options_internal::ParseFlag(text);
    if (!v) return "true or false";
    o.*field = *v;
    return {};
  };
  return Add(std::move(f));
}

template <typename T>
OptionTable<T>& OptionTable<T>::Text(std::string key, std::string T::*field, std::string doc) {
  Field f;
  f.info = {std::move(key), OptionKind::kText, "", "", std::move(doc), {}, {}};
  f.get = [field](const T& o) { return o.*field; };
  f.set = [field](T& o, std::string_view text) -> std::string {
    o.*field = std::string(text);
    return {};
  };
  return Add(std::move(f));
}

template <typename T>
OptionTable<T>& OptionTable<T>::Path(std::string key, std::filesystem::path T::*field,
                                     std::string doc) {
  Field f;
  f.info = {std::move(key), OptionKind::kText, "", "", std::move(doc), {}, {}};
  f.get = [field](const T& o) { return (o.*field).string(); };
  f.set = [field](T& o, std::string_view text) -> std::string {
    o.*field = std::filesystem::path(std::string(text));
    return {};
  };
  return Add(std::move(f));
}

template <typename T>
OptionTable<T>& OptionTable<T>::TextList(std::string key, std::vector<std::string> T::*field,
                                         std::string doc) {
  Field f;
  f.info = {std::move(key), OptionKind::kTextList, "", "", std::move(doc), {}, {}};
  f.get = [field](const T& o) { return options_internal::Join(o.*field, ","); };
  f.set = [field](T& o, std::string_view text) -> std::string {
    o.*field = options_internal::SplitList(text);
    return {};
  };
  return Add(std::move(f));
}

template <typename T>
template <typename E>
OptionTable<T>& OptionTable<T>::Choice(std::string key, E T::*field,
                                       std::vector<std::pair<E, std::string>> names,
                                       std::string doc) {
  std::vector<std::string> choices;
  for (const auto& [value, name] : names) choices.push_back(name);
  Field f;
  f.info = {
      key,    OptionKind::kChoice, "", options_internal::Join(choices, ", "), std::move(doc), {},
      choices};
  f.get = [field, names](const T& o) -> std::string {
    for (const auto& [value, name] : names) {
      if (o.*field == value) return name;
    }
    return std::to_string(static_cast<int64_t>(o.*field));
  };
  const std::string expected = "one of " + options_internal::Join(choices, ", ");
  f.set = [field, names, expected](T& o, std::string_view text) -> std::string {
    for (const auto& [value, name] : names) {
      if (text == name) {
        o.*field = value;
        return {};
      }
    }
    return expected;
  };
  f.check = [field, names, key](const T& o, std::vector<std::string>& problems) {
    for (const auto& [value, name] : names) {
      if (o.*field == value) return;
    }
    problems.push_back(key + " (" + std::to_string(static_cast<int64_t>(o.*field)) +
                       ") is not a known value");
  };
  return Add(std::move(f));
}

template <typename T>
OptionTable<T>& OptionTable<T>::RealList(std::string key, std::vector<double> T::*field,
                                         std::string unit, ValueRange each, size_t min_size,
                                         size_t max_size, std::string doc) {
  using namespace options_internal;
  const std::string size = min_size == max_size ? std::to_string(min_size) + " values"
                                                : std::to_string(min_size) + " to " +
                                                      std::to_string(max_size) + " values";
  Field f;
  f.info = {key,
            OptionKind::kRealList,
            unit,
            size + (each.ToString().empty() ? "" : ", each " + each.ToString()),
            std::move(doc),
            {},
            {}};
  f.get = [field](const T& o) {
    std::vector<std::string> items;
    for (double v : o.*field) items.push_back(FormatReal(v));
    return Join(items, ",");
  };
  f.set = [field](T& o, std::string_view text) -> std::string {
    std::vector<double> values;
    for (const std::string& item : SplitList(text)) {
      const std::optional<double> v = ParseReal(item);
      if (!v) return "a comma-separated list of finite numbers";
      values.push_back(*v);
    }
    o.*field = std::move(values);
    return {};
  };
  f.check = [field, key, unit, each, min_size, max_size, size](const T& o,
                                                               std::vector<std::string>& problems) {
    const std::vector<double>& values = o.*field;
    if (values.size() < min_size || values.size() > max_size) {
      problems.push_back(key + " has " + std::to_string(values.size()) + " values, must have " +
                         size);
    }
    for (size_t i = 0; i < values.size(); ++i) {
      const double v = values[i];
      if (std::isfinite(v) && each.Contains(v)) continue;
      problems.push_back(key + "[" + std::to_string(i) + "] (" + FormatReal(v) +
                         (unit.empty() || !std::isfinite(v) ? "" : " " + unit) + ") must be " +
                         (std::isfinite(v) ? each.Requirement() : "finite"));
    }
  };
  return Add(std::move(f));
}

template <typename T>
template <typename U>
OptionTable<T>& OptionTable<T>::Nested(const std::string& prefix, U T::*field,
                                       const OptionTable<U>& sub) {
  for (const typename OptionTable<U>::Field& s : sub.fields_) {
    Field f;
    f.info = s.info;
    f.info.key = prefix + "." + s.info.key;
    f.get = [field, get = s.get](const T& o) { return get(o.*field); };
    f.set = [field, set = s.set](T& o, std::string_view text) { return set(o.*field, text); };
    if (s.check) {
      const std::string key = f.info.key;
      f.check = [field, check = s.check, prefix](const T& o, std::vector<std::string>& problems) {
        const size_t before = problems.size();
        check(o.*field, problems);
        for (size_t i = before; i < problems.size(); ++i) problems[i] = prefix + "." + problems[i];
      };
    }
    Add(std::move(f));
  }
  for (const typename OptionTable<U>::Rule& rule : sub.rules_) {
    rules_.push_back([field, rule, prefix](const T& o, std::vector<std::string>& problems) {
      const size_t before = problems.size();
      rule(o.*field, problems);
      for (size_t i = before; i < problems.size(); ++i) problems[i] = prefix + "." + problems[i];
    });
  }
  return *this;
}

template <typename T>
OptionTable<T>& OptionTable<T>::Add(Field field) {
  AVP_THROW_UNLESS(!field.info.key.empty() && Find(field.info.key) == nullptr, field.info.key,
                   noun_);
  fields_.push_back(std::move(field));
  return *this;
}

template <typename T>
const typename OptionTable<T>::Field* OptionTable<T>::Find(std::string_view key) const {
  for (const Field& f : fields_) {
    if (f.info.key == key) return &f;
  }
  return nullptr;
}

template <typename T>
std::vector<std::string> OptionTable<T>::Keys() const {
  std::vector<std::string> keys;
  keys.reserve(fields_.size());
  for (const Field& f : fields_) keys.push_back(f.info.key);
  return keys;
}

template <typename T>
std::vector<OptionInfo> OptionTable<T>::Info(const T& defaults) const {
  std::vector<OptionInfo> out;
  out.reserve(fields_.size());
  for (const Field& f : fields_) {
    out.push_back(f.info);
    out.back().default_value = f.get(defaults);
  }
  return out;
}

template <typename T>
Status OptionTable<T>::Set(T& options, std::string_view key, std::string_view value) const {
  const Field* f = Find(key);
  if (f == nullptr) {
    return InvalidArgumentError("unknown " + noun_ + " '" + std::string(key) +
                                "' (known: " + options_internal::Join(Keys(), ", ") + ")" +
                                DidYouMean(key, Keys()));
  }
  const std::string expected = f->set(options, value);
  if (expected.empty()) return Status::Ok();
  return InvalidArgumentError(noun_ + " " + std::string(key) + ": '" + std::string(value) +
                              "' is not " + expected);
}

template <typename T>
Status OptionTable<T>::SetAll(T& options, const OptionValues& values) const {
  for (const auto& [key, value] : values) AVP_RETURN_IF_ERROR(Set(options, key, value));
  return Status::Ok();
}

template <typename T>
std::optional<std::string> OptionTable<T>::Get(const T& options, std::string_view key) const {
  const Field* f = Find(key);
  if (f == nullptr) return std::nullopt;
  return f->get(options);
}

template <typename T>
OptionValues OptionTable<T>::Values(const T& options) const {
  OptionValues out;
  out.reserve(fields_.size());
  for (const Field& f : fields_) out.emplace_back(f.info.key, f.get(options));
  return out;
}

template <typename T>
OptionValues OptionTable<T>::Differences(const T& options, const T& base) const {
  OptionValues out;
  for (const Field& f : fields_) {
    std::string v = f.get(options);
    if (v != f.get(base)) out.emplace_back(f.info.key, std::move(v));
  }
  return out;
}

template <typename T>
std::vector<std::string> OptionTable<T>::Problems(const T& options) const {
  std::vector<std::string> problems;
  for (const Field& f : fields_) {
    if (f.check) f.check(options, problems);
  }
  for (const Rule& rule : rules_) rule(options, problems);
  return problems;
}

template <typename T>
Status OptionTable<T>::Validate(const T& options) const {
  const std::vector<std::string> problems = Problems(options);
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError("invalid " + noun_ + "s: " + options_internal::Join(problems, "; "));
}

template <typename T>
AnyOptions::AnyOptions(const OptionTable<T>& table, T value)
    : impl_(std::make_unique<Model<T>>(&table, std::move(value))) {}

template <typename T>
const T& AnyOptions::As() const {
  AVP_THROW_UNLESS(impl_ != nullptr && impl_->type() == typeid(T), typeid(T).name());
  return *static_cast<const T*>(impl_->value());
}

}  // namespace avp
