// Pre-screening: the model ranks an optimiser's candidates and only the most promising are simulated.
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace demcal::surrogate {

using detail::vector_json;

nlohmann::json ScreenReport::to_json() const {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& c : candidates)
    list.push_back({{"slot", c.slot},
                    {"x", vector_json(c.physical)},
                    {"pool", c.pool},
                    {"replaced", c.replaced},
                    {"simulated", c.simulated},
                    {"predicted_fitness", c.prediction.fitness},
                    {"predicted_mean", c.prediction.mean},
                    {"predicted_sd", c.prediction.sd},
                    {"failure_probability", c.prediction.failure_probability},
                    {"score", c.score}});
  return {{"pool", pool}, {"simulated", simulated}, {"candidates", list}};
}

ScreenReport prescreen(optimise::Optimiser& optimiser, const SurrogateModel& model, const SurrogateOptions& options) {
  if (!optimiser.can_substitute()) throw std::logic_error(optimiser.name() + ": cannot be pre-screened");
  if (!model.usable()) throw std::logic_error("prescreen: the surrogate model is not fitted");
  const auto batch = optimiser.ask();
  const auto& space = optimiser.space();
  ScreenReport report;
  for (size_t i = 0; i < batch.size(); ++i) {
    std::vector<Eigen::VectorXd> pool = {batch[i]};
    if (options.pool_factor > 1) {
      auto alternatives = optimiser.alternatives(i, options.pool_factor - 1);
      pool.insert(pool.end(), alternatives.begin(), alternatives.end());
    }
    ScreenedCandidate best;
    best.slot = static_cast<int>(i);
    best.pool = static_cast<int>(pool.size());
    best.score = -HUGE_VAL;
    for (size_t j = 0; j < pool.size(); ++j) {
      const Prediction p = model.predict(space.to_unit(pool[j]));
      const double s = model.score(p);
      if (s > best.score) {  // ties keep the optimiser's own proposal
        best.score = s;
        best.prediction = p;
        best.physical = pool[j];
        best.replaced = j > 0;
      }
    }
    if (best.replaced) optimiser.substitute(i, best.physical);
    report.pool += best.pool;
    report.candidates.push_back(best);
  }
  const size_t keep = options.k > 0 ? std::min(batch.size(), static_cast<size_t>(options.k)) : batch.size();
  std::vector<size_t> order(batch.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return report.candidates[a].score > report.candidates[b].score; });
  for (size_t r = 0; r < order.size(); ++r) {
    auto& c = report.candidates[order[r]];
    c.simulated = r < keep;
    if (!c.simulated) optimiser.withdraw(order[r]);
  }
  report.simulated = static_cast<int>(keep);
  return report;
}

}  // namespace demcal::surrogate
