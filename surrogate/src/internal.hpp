// Private to the surrogate module: what its sources share (JSON of vectors and matrices, the
// held-out relative error, reading an options struct by its field table).
#pragma once

#include "demcal/common/field_table.hpp"
#include "demcal/limits/limits.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace demcal::surrogate::detail {

inline nlohmann::json vector_json(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

inline Eigen::VectorXd vector_from(const nlohmann::json& j) {
  const auto v = j.get<std::vector<double>>();
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

// A matrix as JSON rows, and back (a ragged row is an error).
inline nlohmann::json matrix_json(const Eigen::MatrixXd& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    std::vector<double> row(static_cast<size_t>(m.cols()));
    for (Eigen::Index j = 0; j < m.cols(); ++j) row[static_cast<size_t>(j)] = m(i, j);
    rows.push_back(row);
  }
  return rows;
}

inline Eigen::MatrixXd matrix_from(const nlohmann::json& j) {
  const auto rows = j.get<std::vector<std::vector<double>>>();
  Eigen::MatrixXd m(static_cast<Eigen::Index>(rows.size()), rows.empty() ? 0 : static_cast<Eigen::Index>(rows[0].size()));
  for (size_t i = 0; i < rows.size(); ++i) {
    if (static_cast<Eigen::Index>(rows[i].size()) != m.cols()) throw std::invalid_argument("ragged matrix");
    for (size_t k = 0; k < rows[i].size(); ++k) m(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = rows[i][k];
  }
  return m;
}

// Held-out relative error: mean |ŷ − y| / mean |y − mean(y)| from the absolute errors and the
// observed values (0 when the values do not spread).
inline double relative_error(const std::vector<double>& absolute_errors, const std::vector<double>& observed) {
  const double mean = std::accumulate(observed.begin(), observed.end(), 0.0) / static_cast<double>(observed.size());
  double spread = 0;
  for (double y : observed) spread += std::abs(y - mean);
  return spread > 0 ? std::accumulate(absolute_errors.begin(), absolute_errors.end(), 0.0) / spread : 0.0;
}

// Reads `json` key by key (in key order) with the field of `fields` of that name (its raw
// reader, Field::read); errors name `where`, the key and its value (a nested object's reader names
// its own key), an unknown key included. The result is validated (Validate()).
template <class Options>
Options options_from_json(const nlohmann::json& json, const std::string& where, const FieldTable<Options>& fields) {
  if (!json.is_object()) throw std::invalid_argument(where + ": must be an object");
  Options o;
  for (const auto& [key, value] : json.items()) {
    try {
      const Field<Options>* field = fields.find(key);
      if (field == nullptr) throw std::invalid_argument("unknown key");
      field->read(o, value, where);
    } catch (const std::exception& e) {
      const std::string located = where + "." + key, what = e.what();
      if (what.rfind(located, 0) == 0) throw;  // a nested object's reader has named it already
      throw std::invalid_argument(located + " = " + value.dump() + ": " + what);
    }
  }
  try {
    o.Validate();
  } catch (const std::exception& e) {
    throw std::invalid_argument(where + ": " + e.what());
  }
  return o;
}

}  // namespace demcal::surrogate::detail
