#pragma once

// Components and placement: components declare their ports and name no
// medium (component.hpp); a host builds the ones a plan puts in its process,
// linking each port in-process, through Shm or through Optimus
// (host.hpp), as a system file's placement says (system_file.hpp, main.hpp);
// a harness tests one alone (harness.hpp).
#include "prime/system/component.hpp"
#include "prime/system/context.hpp"
#include "prime/system/harness.hpp"
#include "prime/system/host.hpp"
#include "prime/system/main.hpp"
#include "prime/system/plan.hpp"
#include "prime/system/registry.hpp"
#include "prime/system/system_file.hpp"
