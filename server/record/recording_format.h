// The recording container lives in protocol/recording_format.h (the live
// broadcast's players parse its records on the client side too).
#pragma once

#include "protocol/recording_format.h"
