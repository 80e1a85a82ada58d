#pragma once
// cpm::security — a lab secured with DDS Security (Fast DDS's builtin plugins: PKI-DH
// authentication, Access-Permissions, AES-GCM-GMAC encryption).
//
// A lab's folder (made once by `cpm security init DIR`):
//   DIR/identity_ca.cert.pem, identity_ca.key.pem         signs the nodes' certificates
//   DIR/permissions_ca.cert.pem, permissions_ca.key.pem   signs governance and permissions only
//   DIR/governance.xml, governance.p7s                    every topic authenticated, access
//                                                          controlled and encrypted; discovery too
//   DIR/nodes/NAME/                                        one per node (`cpm security add-node`)
// A node's folder holds everything that node needs and nothing it must not have (no CA key), so
// it alone is copied to the machine the node runs on:
//   cert.pem, key.pem, permissions.xml, permissions.p7s, identity_ca.cert.pem,
//   permissions_ca.cert.pem, governance.p7s
//
// Two CAs, because Fast DDS 2.9.1 accepts a policy file signed by any certificate that chains
// to the permissions CA: no node certificate may chain to it.
#include <string>
#include <utility>
#include <vector>

namespace cpm::security {

/// Makes a lab's folder: both CAs (EC P-256, valid `days`), the governance, signed. Throws
/// cpm::Error when `dir` already holds a lab (keys are never overwritten) or openssl fails.
void init_lab(const std::string& dir, int days = 3650);

/// What one node may do. Topic names may use `*` and `?` (fnmatch patterns).
struct Grant
{
    std::vector<std::string> publish;
    std::vector<std::string> subscribe;
    int days = 3650;  ///< validity of the certificate and the permissions
};

/// Issues node `name` ([A-Za-z0-9_-]+): its key, its certificate from the identity CA and its
/// permissions (the grant plus the builtin topics; with any subscription, the history's
/// historyRequest, historyReply and historyReply/T for each T it may subscribe) signed by the
/// permissions CA, into
/// DIR/nodes/NAME/ (returned). Throws cpm::Error naming what is wrong (no lab in `dir`, a bad
/// name or topic, a node that exists already, openssl failing).
std::string add_node(const std::string& dir, const std::string& name, const Grant& grant);

/// The files of a node's folder, checked: throws cpm::Error naming the folder and the file
/// that is missing.
struct NodeFiles
{
    std::string identity_ca, certificate, private_key, permissions_ca, governance, permissions;
    std::string permissions_xml;  ///< the readable copy of the signed permissions
};
NodeFiles node_files(const std::string& node_dir);
/// The files of a node's folder, all node_files() reads (no CA's key among them): what another
/// host needs to run the node.
inline constexpr const char* kNodeFileNames[] = {"identity_ca.cert.pem", "cert.pem",       "key.pem",        "permissions_ca.cert.pem",
                                                 "governance.p7s",       "permissions.p7s", "permissions.xml"};

/// The DomainParticipantQos properties that make a participant secure with these files.
std::vector<std::pair<std::string, std::string>> participant_properties(const NodeFiles& files);

/// What a node's permissions allow on a topic; empty when allowed, else why not, naming the
/// topic, the node and the rule: "this node (CN=viewer,O=cpm lab) may not publish
/// 'vehicleCommandDirect': its permissions (…/permissions.xml) allow publishing log, readyStatus,
/// parameterRequest".
std::string why_not_allowed(const NodeFiles& files, const std::string& topic, bool publish);

}  // namespace cpm::security
