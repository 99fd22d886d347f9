// Field tables (field_table.hpp): one table drives the unknown-key check, checked reading and
// to_json; the messages are those of docs/bad-input.md.
#include <demcal/common/field_table.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

using demcal::custom_field;
using demcal::field;
using demcal::FieldTable;
using demcal::named_field;
using nlohmann::json;

namespace {

enum class Shape { round, square };

Shape parse_shape(const std::string& name) {
  if (name == "round") return Shape::round;
  if (name == "square") return Shape::square;
  throw std::invalid_argument("shape '" + name + "': expected round or square");
}

std::string shape_name(Shape shape) { return shape == Shape::round ? "round" : "square"; }

struct Inner {
  int count = 2;
};

struct Options {
  int size = 3;
  double scale = 1.5;
  bool enabled = false;
  std::string label = "a";
  Shape shape = Shape::round;
  Inner inner;
  double limit = std::numeric_limits<double>::infinity();
};

const FieldTable<Options>& options_fields() {
  static const FieldTable<Options> table{
      field("size", &Options::size),
      field("scale", &Options::scale),
      field("enabled", &Options::enabled).flag("Switch it on"),
      field("label", &Options::label),
      named_field("shape", &Options::shape, parse_shape, shape_name),
      field<Options>("count", [](auto& o) -> auto& { return o.inner.count; }),
      custom_field<Options>(
          "limit", [](Options& o, const json& value, const std::string&) { o.limit = value.is_null() ? HUGE_VAL : value.get<double>(); },
          [](const Options& o) -> std::optional<json> {
            if (std::isinf(o.limit)) return std::nullopt;
            return o.limit;
          }),
  };
  return table;
}

std::string read_error(const json& j) {
  Options o;
  try {
    options_fields().read<std::runtime_error>(j, o, "f.json: options");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(FieldTable, ReadsPresentKeysAndKeepsTheOthers) {
  Options o;
  options_fields().read<std::runtime_error>({{"size", 7}, {"shape", "square"}, {"count", 5}, {"limit", 2.5}}, o, "w");
  EXPECT_EQ(o.size, 7);
  EXPECT_EQ(o.shape, Shape::square);
  EXPECT_EQ(o.inner.count, 5);
  EXPECT_EQ(o.limit, 2.5);
  EXPECT_EQ(o.scale, 1.5);
  EXPECT_EQ(o.label, "a");
}

TEST(FieldTable, UnknownKeyListsEveryKeySorted) {
  EXPECT_EQ(read_error({{"sise", 1}}),
            "f.json: options: unknown key 'sise' (known: count, enabled, label, limit, scale, shape, size)");
  EXPECT_EQ(read_error(json::array()), "f.json: options: expected a JSON object, got []");
}

TEST(FieldTable, WrongTypeAndNonFiniteNameTheKeyAndValue) {
  EXPECT_EQ(read_error({{"size", "ten"}}), "f.json: options.size: expected an integer, got \"ten\"");
  EXPECT_EQ(read_error({{"enabled", 1}}), "f.json: options.enabled: expected true or false, got 1");
  EXPECT_EQ(read_error({{"shape", 3}}), "f.json: options.shape: expected a string, got 3");
  EXPECT_EQ(read_error({{"scale", std::numeric_limits<double>::infinity()}}),
            "f.json: options.scale: value must be finite, got null");
  EXPECT_EQ(read_error({{"size", std::string(70, 'x')}}),
            "f.json: options.size: expected an integer, got \"" + std::string(59, 'x') + "...");
}

TEST(FieldTable, NamedValueAndCustomFieldErrorsPassUnchanged) {
  EXPECT_EQ(read_error({{"shape", "oval"}}), "shape 'oval': expected round or square");
  EXPECT_EQ(read_error({{"limit", "x"}}).find("[json.exception.type_error.302]"), 0u);
}

TEST(FieldTable, FirstBadFieldInTableOrderIsReported) {
  EXPECT_EQ(read_error({{"label", 1}, {"size", "x"}}), "f.json: options.size: expected an integer, got \"x\"");
}

TEST(FieldTable, ToJsonWritesEachFieldLeavingOutNullopt) {
  Options o;
  EXPECT_EQ(options_fields().to_json(o),
            json({{"size", 3}, {"scale", 1.5}, {"enabled", false}, {"label", "a"}, {"shape", "round"}, {"count", 2}}));
  o.limit = 4;
  EXPECT_EQ(options_fields().to_json(o).at("limit"), 4.0);
}

TEST(FieldTable, ReadingWhatToJsonWroteGivesTheSameOptions) {
  Options o;
  o.size = 9;
  o.shape = Shape::square;
  o.inner.count = 1;
  Options back;
  options_fields().read<std::runtime_error>(options_fields().to_json(o), back, "w");
  EXPECT_EQ(options_fields().to_json(back), options_fields().to_json(o));
}

TEST(FieldTable, FlagsAndTheirTargets) {
  Options o;
  const auto* enabled = options_fields().find("enabled");
  ASSERT_NE(enabled, nullptr);
  EXPECT_EQ(enabled->help, "Switch it on");
  EXPECT_EQ(std::get<bool*>(enabled->flag_target(o)), &o.enabled);
  const auto target = std::get<demcal::NamedValue>(options_fields().find("shape")->flag_target(o));
  EXPECT_EQ(target.name, "round");
  target.set("square");
  EXPECT_EQ(o.shape, Shape::square);
  EXPECT_FALSE(options_fields().find("limit")->flag_target);
  EXPECT_EQ(options_fields().find("nope"), nullptr);
}
