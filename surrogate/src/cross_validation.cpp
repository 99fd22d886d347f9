// Cross-validation of a surrogate on archived rows: error, 90 % interval coverage, failure Brier score.
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace demcal::surrogate {

nlohmann::json CrossValidation::to_json() const {
  return {{"rows", rows},
          {"finite_rows", finite_rows},
          {"failed_rows", failed_rows},
          {"folds", folds},
          {"mean_absolute_error", mean_absolute_error},
          {"relative_error", relative_error},
          {"median_relative_error", median_relative_error},
          {"coverage90", coverage90},
          {"failure_brier", failure_brier}};
}

CrossValidation cross_validate(const std::vector<TrainingRow>& rows, const SurrogateOptions& options, int folds,
                               const CurveHooks& hooks) {
  if (folds < 2) throw std::invalid_argument("cross_validate: folds = " + std::to_string(folds) + " must be >= 2");
  CrossValidation cv;
  cv.rows = static_cast<long>(rows.size());
  cv.folds = folds;
  std::vector<double> abs_errors, rel_errors, ys;
  long covered = 0;
  double brier = 0;
  for (int f = 0; f < folds; ++f) {
    std::vector<TrainingRow> train, test;
    for (size_t i = 0; i < rows.size(); ++i) (static_cast<int>(i % static_cast<size_t>(folds)) == f ? test : train).push_back(rows[i]);
    SurrogateModel model(options, hooks);
    if (test.empty() || !model.fit(train)) continue;
    for (const auto& r : test) {
      if (options.kind == "mlp" && std::isfinite(r.fitness) && r.outputs.size() == 0) continue;
      const Prediction p = model.predict(r.unit);
      const bool failed = !std::isfinite(r.fitness);
      brier += (p.failure_probability - (failed ? 1.0 : 0.0)) * (p.failure_probability - (failed ? 1.0 : 0.0));
      if (failed) {
        ++cv.failed_rows;
        continue;
      }
      ++cv.finite_rows;
      abs_errors.push_back(std::abs(p.fitness - r.fitness));
      if (r.fitness != 0) rel_errors.push_back(std::abs(p.fitness - r.fitness) / std::abs(r.fitness));
      ys.push_back(r.fitness);
      const auto [lo, hi] = model.interval(r.unit, 0.9);
      if (r.fitness >= lo && r.fitness <= hi) ++covered;
    }
  }
  if (cv.finite_rows == 0) return cv;
  cv.mean_absolute_error = std::accumulate(abs_errors.begin(), abs_errors.end(), 0.0) / static_cast<double>(abs_errors.size());
  cv.relative_error = detail::relative_error(abs_errors, ys);
  if (!rel_errors.empty()) {
    std::nth_element(rel_errors.begin(), rel_errors.begin() + static_cast<long>(rel_errors.size() / 2), rel_errors.end());
    cv.median_relative_error = rel_errors[rel_errors.size() / 2];
  }
  cv.coverage90 = static_cast<double>(covered) / static_cast<double>(cv.finite_rows);
  cv.failure_brier = brier / static_cast<double>(cv.finite_rows + cv.failed_rows);
  return cv;
}

}  // namespace demcal::surrogate
