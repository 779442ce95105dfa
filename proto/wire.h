// The plenoxd.v1 messages under a short name for the codecs of this folder and their callers.
#pragma once

#include "plenoxd/v1/plenoxd.pb.h"

namespace plx {
namespace pb = ::plenoxd::v1;
}  // namespace plx
