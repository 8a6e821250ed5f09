// The least-squares pieces that curve and patch fitting share (internal to the reeb module, so
// Eigen's headers stay out of bspline.h).
#pragma once
#include <Eigen/Dense>

#include <vector>

namespace vdbsurf::reeb {

// Row s holds the cubic basis functions of the knots at params[s] (n columns).
Eigen::MatrixXd basisMatrix(const std::vector<double>& knots, int n, const std::vector<double>& params);

// Solves min |B X - R|^2 + lambda |D X|^2 for X, with D the second differences of X's rows
// (cyclic when `cyclic`), lambda small against B^T B, and a whisper of ridge so that the system
// stays definite when the samples leave a control point unseen and there is nothing to bend.
Eigen::MatrixXd penalizedLeastSquares(const Eigen::MatrixXd& B, const Eigen::MatrixXd& R, bool cyclic);

} // namespace vdbsurf::reeb
