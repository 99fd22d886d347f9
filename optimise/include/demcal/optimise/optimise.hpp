// Umbrella header of the optimise module: parameter spaces, the ask/tell optimisers (PSO, TBPSO,
// GA, NLopt), the TBPSO trust arithmetic and the analytic test functions.
#pragma once

#include "demcal/optimise/optimiser.hpp"
#include "demcal/optimise/parameter_space.hpp"
#include "demcal/optimise/swarm.hpp"
#include "demcal/optimise/test_functions.hpp"
