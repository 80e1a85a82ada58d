#pragma once
#include <string>
#include <vector>

extern const char* kVehicleSimHelp;
/// `cpm vehicle sim ...` (arguments after the two command words).
int vehicle_sim(const std::vector<std::string>& args);
