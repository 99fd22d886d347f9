// The arithmetic of the trust-based PSO (TBPSO, paper eqs. 11-14), exposed so it can be checked
// by hand and reused. Positions are rows (one particle per row) in unit-cube coordinates.
#pragma once

#include "demcal/optimise/optimiser.hpp"

#include <Eigen/Core>

namespace demcal::optimise {

// Eq. 11: d_rel,ij = d_ij / Σ_k d_ik with d the Euclidean distance between rows i and j.
// A row whose distances are all zero (every particle on top of particle i) gets zeros.
Eigen::MatrixXd tbpso_relative_distances(const Eigen::MatrixXd& positions);

// Eq. 12, applied to every pair (i, j), i != j (the diagonal stays 0):
//   C_ij = 0               if f(p_i) <= f(p_j)
//   C_ij = C_ij(prev) + 1  if f(p_i) >  f(p_j) and f(x_j) <= f(p_j)
//   C_ij = C_ij(prev) - 1  if f(p_i) >  f(p_j) and f(x_j) >  f(p_j)
// personal_best_values are f(p) AFTER the personal bests were updated with this iteration's
// values current_values = f(x); so f(x_j) <= f(p_j) holds exactly when x_j is (or ties) j's best,
// i.e. when j just improved. Non-finite values must already be mapped to +inf.
Eigen::MatrixXd tbpso_trust_update(const Eigen::MatrixXd& previous_trust,
                                   const Eigen::VectorXd& personal_best_values,
                                   const Eigen::VectorXd& current_values);

// Eqs. 13-14: row i of the result is T_i = Σ_j d_rel,ij C_ij Δx_ij with Δx_ij = x_j − x_i
// (TrustDirection::toward) or x_i − x_j (TrustDirection::paper).
Eigen::MatrixXd tbpso_trust_pull(const Eigen::MatrixXd& positions, const Eigen::MatrixXd& trust,
                                 TrustDirection direction);

// Constriction factor of eq. 8, K = 2 / |2 − φ − sqrt(φ² − 4φ)|; throws std::invalid_argument for φ < 4.
double constriction_factor(double phi);

}  // namespace demcal::optimise
