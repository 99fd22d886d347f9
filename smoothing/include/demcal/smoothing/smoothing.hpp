// The whole smoothing module: curves, objective functions 1 and 2, smoothers, synthetic curves, plots.
#pragma once

#include "demcal/smoothing/curve.hpp"
#include "demcal/smoothing/objective.hpp"
#include "demcal/smoothing/plot.hpp"
#include "demcal/smoothing/smoother.hpp"
#include "demcal/smoothing/synthetic.hpp"
