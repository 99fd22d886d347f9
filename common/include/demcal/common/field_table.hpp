// Field tables: the JSON keys of an options struct declared once, each beside its member (or a
// reader and writer of its own). One table drives
//   - the unknown-key check: "<where>: unknown key 'k' (known: <the table's keys, sorted>)",
//   - checked reading: JSON of the wrong type is "<where>.<key>: expected an integer, got "ten"",
//     a number must be finite ("<where>.<key>: value must be finite, got ..."),
//   - writing (to_json): every field, or those whose writer gives a value,
//   - command-line flags: a field given a help text (.flag) is the option --<key> ('_' as '-') of
//     a command that binds the table (pipelines/cli/field_flags.hpp).
//
//   struct Options { int population = 10; double xtol = 0; Bounds bounds = Bounds::clamp; Inner inner; };
//   const FieldTable<Options>& options_fields() {
//     static const FieldTable<Options> table{
//         field("population", &Options::population),                 // get<int>(), checked
//         field("xtol", &Options::xtol).flag("Relative tolerance"),   // also the flag --xtol
//         named_field("bounds", &Options::bounds, parse_bounds, bounds_name),  // an enum by name
//         field<Options>("points", [](auto& o) -> auto& { return o.inner.points; }),  // nested
//         custom_field<Options>("limit", read_limit, write_limit),    // its own reader and writer
//     };
//     return table;
//   }
//   options_fields().read<CampaignError>(json, options, "c.json: optimiser");
//   nlohmann::json out = options_fields().to_json(options);
//
// Adding a key: give the struct its member with a default and the table one row; the key check,
// reading, writing (and a flag, with .flag) follow. Fields are read in table order, so of several
// bad values the first row's is reported.
#pragma once

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace demcal {

// `value` as compact JSON for messages, cut after 60 characters ("...").
std::string describe_json(const nlohmann::json& value);
// "<where>.<key>: expected <expected>, got <value>".
std::string wrong_type_message(const std::string& where, const std::string& key, const char* expected,
                               const nlohmann::json& value);
// "<where>.<key>: value must be finite, got <value>".
std::string non_finite_message(const std::string& where, const std::string& key, const nlohmann::json& value);

// What a JSON value must be to fill a T, in words, for messages: "true or false", "an integer",
// "a number", "a string", else "a value of another type".
template <class T>
constexpr const char* expected_json_kind() {
  if constexpr (std::is_same_v<T, bool>) return "true or false";
  else if constexpr (std::is_integral_v<T>) return "an integer";
  else if constexpr (std::is_floating_point_v<T>) return "a number";
  else if constexpr (std::is_same_v<T, std::string>) return "a string";
  else return "a value of another type";
}

// "<where>: expected a JSON object, got <j>" when `j` is no object; "<where>: unknown key 'k'
// (known: a, b, c)" for its first key (in key order) not in `known`; nullopt when `j` is fine.
std::optional<std::string> unknown_key_message(const nlohmann::json& j, const std::set<std::string>& known,
                                               const std::string& where);

template <class Error>
void reject_unknown_keys(const nlohmann::json& j, const std::set<std::string>& known, const std::string& where) {
  if (auto message = unknown_key_message(j, known, where)) throw Error(*message);
}

// Reads j[key] into `out` when present, checked as a table's typed field is (for keys outside
// any table). Throws Error naming where.key and the value.
template <class Error, class T>
void read_field(const nlohmann::json& j, const std::string& key, T& out, const std::string& where) {
  if (!j.contains(key)) return;
  const nlohmann::json& value = j.at(key);
  try {
    out = value.get<T>();
  } catch (const nlohmann::json::exception&) {
    throw Error(wrong_type_message(where, key, expected_json_kind<T>(), value));
  }
  if constexpr (std::is_floating_point_v<T>) {
    if (!std::isfinite(out)) throw Error(non_finite_message(where, key, value));
  }
}

// What a command-line flag sets: a member of one of these types, or a named value (an enum), set
// from its name.
struct NamedValue {
  std::function<void(const std::string& name)> set;  // throws std::invalid_argument for an unknown name
  std::string name;                                  // the value's name now (the flag's default)
};
using FlagTarget = std::variant<bool*, int*, long*, std::uint64_t*, double*, std::string*, NamedValue>;

// One key of an options struct. Made by field(), named_field() or custom_field() below.
template <class Options>
struct Field {
  std::string key;
  // Sets the field from `value`, the JSON at `key` of the object at `where`. A typed field
  // assigns value.get<T>(), which throws nlohmann::json::exception for JSON of another type.
  std::function<void(Options&, const nlohmann::json& value, const std::string& where)> read;
  // The field's JSON; nullopt leaves the key out of to_json.
  std::function<std::optional<nlohmann::json>(const Options&)> write;
  // FieldTable::read's words for the JSON the field takes ("an integer"): a JSON exception of
  // `read` becomes "<where>.<key>: expected <expected>, got <value>". Null: whatever `read`
  // throws passes unchanged.
  const char* expected = nullptr;
  // Set for floating-point fields: FieldTable::read rejects a value that is not finite.
  std::function<bool(const Options&)> is_finite;
  // Non-empty: the field is also a command-line flag, with this help text.
  std::string help;
  // The member a flag sets; set for fields of a FlagTarget type and named fields.
  std::function<FlagTarget(Options&)> flag_target;

  // The field with another writer (e.g. null for infinity, or nullopt to leave a default out).
  Field writes(std::function<std::optional<nlohmann::json>(const Options&)> writer) && {
    write = std::move(writer);
    return std::move(*this);
  }
  // The field as a command-line flag too (pipelines/cli/field_flags.hpp).
  Field flag(std::string help_text) && {
    help = std::move(help_text);
    return std::move(*this);
  }
  // FieldTable::read passes every exception of this field on unchanged: its owner words them.
  Field unchecked() && {
    expected = nullptr;
    return std::move(*this);
  }
};

// A typed field: `member` is a pointer to a member of Options, or a function Options& -> T& (a
// generic lambda `[](auto& o) -> auto& { return o.inner.value; }` for a nested member). Read with
// get<T>(), written as json(T).
template <class Options, class Member>
Field<Options> field(std::string key, Member member) {
  using T = std::remove_cvref_t<std::invoke_result_t<Member&, Options&>>;
  Field<Options> f;
  f.key = std::move(key);
  f.read = [member](Options& o, const nlohmann::json& value, const std::string&) {
    std::invoke(member, o) = value.get<T>();
  };
  f.write = [member](const Options& o) -> std::optional<nlohmann::json> { return nlohmann::json(std::invoke(member, o)); };
  f.expected = expected_json_kind<T>();
  if constexpr (std::is_floating_point_v<T>)
    f.is_finite = [member](const Options& o) { return std::isfinite(std::invoke(member, o)); };
  if constexpr (std::is_constructible_v<FlagTarget, T*>)
    f.flag_target = [member](Options& o) { return FlagTarget(&std::invoke(member, o)); };
  return f;
}

template <class Options, class T>
Field<Options> field(std::string key, T Options::*member) {
  return field<Options, T Options::*>(std::move(key), member);
}

// A value (an enum) written as its name: read as a string (checked: "expected a string") and
// parse(name), which throws std::invalid_argument for a name it does not know (passed on
// unchanged); written as name(value).
template <class Options, class Member, class Parse, class Name>
Field<Options> named_field(std::string key, Member member, Parse parse, Name name) {
  Field<Options> f;
  f.key = std::move(key);
  f.read = [member, parse](Options& o, const nlohmann::json& value, const std::string&) {
    std::invoke(member, o) = parse(value.get<std::string>());
  };
  f.write = [member, name](const Options& o) -> std::optional<nlohmann::json> {
    return nlohmann::json(name(std::invoke(member, o)));
  };
  f.expected = expected_json_kind<std::string>();
  f.flag_target = [member, parse, name](Options& o) {
    auto& value = std::invoke(member, o);
    return FlagTarget(NamedValue{[&value, parse](const std::string& text) { value = parse(text); }, name(value)});
  };
  return f;
}

template <class Options, class T, class Parse, class Name>
Field<Options> named_field(std::string key, T Options::*member, Parse parse, Name name) {
  return named_field<Options, T Options::*>(std::move(key), member, std::move(parse), std::move(name));
}

// A field with a reader and writer of its own (see Field::read and Field::write); unchecked.
template <class Options>
Field<Options> custom_field(std::string key,
                            std::function<void(Options&, const nlohmann::json& value, const std::string& where)> read,
                            std::function<std::optional<nlohmann::json>(const Options&)> write) {
  Field<Options> f;
  f.key = std::move(key);
  f.read = std::move(read);
  f.write = std::move(write);
  return f;
}

// The fields of one options struct, in reading order.
template <class Options>
class FieldTable {
 public:
  FieldTable(std::initializer_list<Field<Options>> fields) : fields_(fields) {
    for (const auto& f : fields_) keys_.insert(f.key);
  }

  const std::vector<Field<Options>>& fields() const { return fields_; }
  const std::set<std::string>& keys() const { return keys_; }
  // The field of `key`; nullptr when the table has none.
  const Field<Options>* find(std::string_view key) const {
    for (const auto& f : fields_)
      if (f.key == key) return &f;
    return nullptr;
  }

  // Reads the object `j` (at `where`, for messages) into `options`: throws Error (an exception
  // made from the message) for JSON that is no object or has a key the table lacks, then reads
  // each field present, in table order, checked (Field::expected, Field::is_finite). Fields absent
  // from `j` keep their values.
  template <class Error>
  void read(const nlohmann::json& j, Options& options, const std::string& where) const {
    reject_unknown_keys<Error>(j, keys_, where);
    for (const auto& f : fields_) {
      if (!j.contains(f.key)) continue;
      const nlohmann::json& value = j.at(f.key);
      if (f.expected == nullptr) {
        f.read(options, value, where);
        continue;
      }
      try {
        f.read(options, value, where);
      } catch (const nlohmann::json::exception&) {
        throw Error(wrong_type_message(where, f.key, f.expected, value));
      }
      if (f.is_finite && !f.is_finite(options)) throw Error(non_finite_message(where, f.key, value));
    }
  }

  // Every field's JSON (Field::write) as one object; keys whose writer gives nullopt left out.
  nlohmann::json to_json(const Options& options) const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& f : fields_)
      if (auto value = f.write(options)) j[f.key] = std::move(*value);
    return j;
  }

 private:
  std::vector<Field<Options>> fields_;
  std::set<std::string> keys_;
};

}  // namespace demcal
