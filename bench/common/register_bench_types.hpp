#pragma once
// The benchmark's own message type, registered with cpm as any user type would be.
#include <cpm/TopicType.hpp>

#include <BenchPayloadPubSubTypes.h>

CPM_REGISTER_TYPE(BenchPayload)
