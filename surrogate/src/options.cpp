// SurrogateOptions: validation, its JSON field table, and the training rows a model keeps.
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace demcal::surrogate {

std::string to_string(Acquisition a) { return a == Acquisition::expected_improvement ? "ei" : "lcb"; }

Acquisition parse_acquisition(const std::string& text) {
  if (text == "ei") return Acquisition::expected_improvement;
  if (text == "lcb") return Acquisition::lower_confidence_bound;
  throw std::invalid_argument("acquisition = '" + text + "' (expected ei or lcb)");
}

void SurrogateOptions::Validate() const {
  if (kind != "gp" && kind != "mlp") throw std::invalid_argument("surrogate kind = '" + kind + "' (expected gp or mlp)");
  if (pool_factor < 1) throw std::invalid_argument("surrogate pool_factor = " + std::to_string(pool_factor) + " must be >= 1");
  if (k < 0) throw std::invalid_argument("surrogate k = " + std::to_string(k) + " must be >= 0 (0 = the whole batch)");
  if (!(lcb_kappa >= 0) || !std::isfinite(lcb_kappa))
    throw std::invalid_argument("surrogate lcb_kappa = " + format_number(lcb_kappa, round_trip_digits) + " must be finite and >= 0");
  if (min_runs < 3) throw std::invalid_argument("surrogate min_runs = " + std::to_string(min_runs) + " must be >= 3");
  if (max_training_runs < 10)
    throw std::invalid_argument("surrogate max_training_runs = " + std::to_string(max_training_runs) + " must be >= 10");
  if (batch < 0) throw std::invalid_argument("surrogate batch = " + std::to_string(batch) + " must be >= 0 (0 = the backend's workers)");
  if (!(refit_growth >= 1) || !std::isfinite(refit_growth))
    throw std::invalid_argument("surrogate refit_growth = " + format_number(refit_growth, round_trip_digits) +
                                " must be finite and >= 1");
  if (threads < 1) throw std::invalid_argument("surrogate threads = " + std::to_string(threads) + " must be >= 1");
  if (overlap != "auto" && overlap != "always")
    throw std::invalid_argument("surrogate overlap = '" + overlap + "' (expected auto or always)");
  if (!(cost_ratio > 0))
    throw std::invalid_argument("surrogate cost_ratio = " + format_number(cost_ratio, round_trip_digits) +
                                " must be > 0 (infinity: never adapt)");
  limits::require_within(limits::Limit::training_rows, max_training_runs, "surrogate max_training_runs");
  limits::require_within(limits::Limit::population, batch, "surrogate batch");
  limits::require_within(limits::Limit::training_rows, min_runs, "surrogate min_runs");
  limits::require_within(limits::Limit::population, pool_factor, "surrogate pool_factor (candidates ranked per simulated one)");
  limits::require_within(limits::Limit::population, k, "surrogate k");
  gp.Validate();
  mlp.Validate();
}

namespace {

// "cost_ratio": a number, or "inf" (never adapt).
const FieldTable<SurrogateOptions>& surrogate_fields() {
  static const FieldTable<SurrogateOptions> table{
      field("kind", &SurrogateOptions::kind),
      field("pool_factor", &SurrogateOptions::pool_factor),
      field("k", &SurrogateOptions::k),
      named_field("acquisition", &SurrogateOptions::acquisition, parse_acquisition,
                  [](Acquisition a) { return to_string(a); }),
      field("lcb_kappa", &SurrogateOptions::lcb_kappa),
      field("min_runs", &SurrogateOptions::min_runs),
      field("max_training_runs", &SurrogateOptions::max_training_runs),
      field("batch", &SurrogateOptions::batch),
      field("refit_growth", &SurrogateOptions::refit_growth),
      custom_field<SurrogateOptions>(
          "cost_ratio",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string&) {
            o.cost_ratio = value == "inf" ? HUGE_VAL : value.get<double>();
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> {
            return std::isfinite(o.cost_ratio) ? nlohmann::json(o.cost_ratio) : nlohmann::json("inf");
          }),
      field("overlap", &SurrogateOptions::overlap),
      custom_field<SurrogateOptions>(
          "gp",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string& where) {
            o.gp = GpOptions::from_json(value, where + ".gp");
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> { return o.gp.to_json(); }),
      custom_field<SurrogateOptions>(
          "mlp",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string& where) {
            o.mlp = MlpOptions::from_json(value, where + ".mlp");
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> { return o.mlp.to_json(); }),
  };
  return table;
}

}  // namespace

// threads is left out: results do not depend on it.
nlohmann::json SurrogateOptions::to_json() const { return surrogate_fields().to_json(*this); }

SurrogateOptions SurrogateOptions::from_json(const nlohmann::json& j, const std::string& where) {
  return detail::options_from_json(j, where, surrogate_fields());
}

std::vector<TrainingRow> select_training_rows(const std::vector<TrainingRow>& rows, int max_rows) {
  if (static_cast<long>(rows.size()) <= max_rows) return rows;
  std::vector<size_t> order(rows.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const double fa = std::isfinite(rows[a].fitness) ? rows[a].fitness : HUGE_VAL;
    const double fb = std::isfinite(rows[b].fitness) ? rows[b].fitness : HUGE_VAL;
    return fa < fb;
  });
  const size_t best = static_cast<size_t>(max_rows / 2);
  std::vector<bool> take(rows.size(), false);
  for (size_t i = 0; i < best; ++i) take[order[i]] = true;
  std::vector<size_t> rest;
  for (size_t i = 0; i < rows.size(); ++i)
    if (!take[i]) rest.push_back(i);
  const size_t wanted = static_cast<size_t>(max_rows) - best;
  for (size_t j = 0; j < wanted; ++j) take[rest[j * rest.size() / wanted]] = true;
  std::vector<TrainingRow> out;
  for (size_t i = 0; i < rows.size(); ++i)
    if (take[i]) out.push_back(rows[i]);
  return out;
}

}  // namespace demcal::surrogate
