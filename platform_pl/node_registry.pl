:- module(node_registry,
          [ node_property/2,            % ?Node, ?Property
            node_option/3,              % +Node, +Name, -Value
            local_node/1,               % ?Node
            current_node/1,             % -Node
            node_set_current/1,         % +Node
            node_clear_current/0,
            node_set_default/1,         % +Node
            with_node/2,                % +Node, :Goal
            node_accepts/2,             % +Node, +Proofs/Nonce
            ctx_authorized/1,           % +Ctx
            registry_add/2,             % +Node, +Entry
            registry_set_tokens/2,      % +Node, +Tokens
            registry_remove/1,          % +Node
            registry_release_default/1, % +Node
            registry_bound/3,           % ?Node, ?Host:Port, ?Socket
            registry_ident/4            % ?Node, ?Id, ?Advertised, ?StartedAt
          ]).
:- use_module(transport, [token_proof/3, open_key/1]).
:- use_module(node_ctx, [ctx_node/2, ctx_authenticated/1]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- autoload(library(lists), [member/2]).

:- meta_predicate with_node(+, 0).

/** <module> The nodes of this process: records, options, the current node

What node.pl starts and stops, kept for the rest of the platform: each
node's bound address and socket, identity, tokens and options (with
their defaults), which node is the process's default and which is the
calling thread's current one, and whether a connection's peer may make
requests that need authentication. node.pl re-exports the public
predicates; the connection worker and request policy (node_connection.pl,
node_request.pl) import them from here, so that they do not load node.pl.
*/

:- dynamic
    node_info/3,                % Node, Host:Port, ServerSocket
    node_ident/4,               % Node, Id, Advertised, StartedAt
    node_tokens/2,              % Node, Tokens
    node_opt/2,                 % Node, Option
    default_node/1.             % Node

:- thread_local
    current_node_tl/1.

%!  registry_add(+Node, +Entry) is det.
%
%   Record a node that node_start/3 made. Entry is
%   node(Bound, Socket, Id, Advertised, StartedAt, Tokens, Options).

registry_add(Node, node(Bound, Socket, Id, Advertised, Now, Tokens, Options)) :-
    assertz(node_info(Node, Bound, Socket)),
    assertz(node_ident(Node, Id, Advertised, Now)),
    assertz(node_tokens(Node, Tokens)),
    forall(member(O, Options), assertz(node_opt(Node, O))).

%!  registry_remove(+Node) is det.
%
%   Forget the records of a stopped node.

registry_remove(Node) :-
    retractall(node_info(Node, _, _)),
    retractall(node_ident(Node, _, _, _)),
    retractall(node_tokens(Node, _)),
    retractall(node_opt(Node, _)).

%!  registry_release_default(+Node) is det.
%
%   Node stopped: if it was the default node, another node (if any) is;
%   it is no longer the calling thread's current node.

registry_release_default(Node) :-
    (   retract(default_node(Node))
    ->  (   node_info(Other, _, _)
        ->  assertz(default_node(Other))
        ;   true
        )
    ;   true
    ),
    retractall(current_node_tl(Node)).

%!  registry_bound(?Node, ?Bound, ?Socket) is nondet.
%!  registry_ident(?Node, ?Id, ?Advertised, ?StartedAt) is nondet.
%
%   The bound address and listening socket of a node of this process;
%   its id, advertised address and start time.

registry_bound(Node, Bound, Socket) :-
    node_info(Node, Bound, Socket).

registry_ident(Node, Id, Advertised, StartedAt) :-
    node_ident(Node, Id, Advertised, StartedAt).

%!  node_property(?Node, ?Property) is nondet.
%
%   Properties: id(Id) (32 hex digits), address(Host:Port) (the
%   advertised address), link((Host,Port)) (the same as a Tartarus link),
%   bind(Host:Port) (the bound address), tokens(List), default (if it is
%   the process's default node), option(Option).

node_property(Node, Property) :-
    node_ident(Node, _, Address, _),
    node_property_(Property, Node, Address).

node_property_(id(Id), Node, _) :-
    node_ident(Node, Id, _, _).
node_property_(address(Address), _, Address).
node_property_(link((H,P)), _, H:P).
node_property_(bind(Bound), Node, _) :-
    node_info(Node, Bound, _).
node_property_(tokens(Tokens), Node, _) :-
    node_tokens(Node, Tokens).
node_property_(default, Node, _) :-
    default_node(Node).
node_property_(option(O), Node, _) :-
    node_opt(Node, O).

%!  node_option(+Node, +Name, -Value) is det.
%
%   Value of option Name of Node, or its default.

node_option(Node, Name, Value) :-
    Opt =.. [Name, V0],
    (   node_opt(Node, Opt)
    ->  Value = V0
    ;   Name == max_unauth_connections
    ->  node_option(Node, max_connections, Max),
        Value is max(1, Max // 2)
    ;   option_default(Name, Value)
    ).

option_default(max_connections, 64).
option_default(idle_timeout, 10).
option_default(auth_idle_timeout, 60).
option_default(store, none).
option_default(settle_period, 2).
option_default(lease_s, 10).
option_default(max_frame_size, 33554432).
option_default(max_text_frame_size, 4096).
option_default(frame_deadline, 5).
option_default(max_term_depth, 64).
option_default(max_unauth_per_peer, 16).
option_default(reply_timeout, 30).
option_default(connect_timeout, 5).
option_default(commit_timeout, 10).
option_default(tls, none).
option_default(tls_peers, any).
option_default(agent_cpu_limit, 2).
option_default(agent_stack_limit, 268435456).
option_default(agent_module_limit, 67108864).
option_default(agent_post_limit, 600).
option_default(agent_log_limit, 200).
option_default(max_agents, 100).
option_default(clone_limit, 60).
option_default(agent_memory_budget, 1073741824).
option_default(max_running_agents, 8).
option_default(agent_slot_wait, 60).
option_default(agent_wall_limit, 60).
option_default(agent_idle_limit, 600).
option_default(max_agents_per_peer, 50).
option_default(max_running_per_peer, 4).
option_default(peer_post_limit, 6000).

%!  local_node(?Node) is nondet.
%
%   Node is a platform running in this process.

local_node(Node) :-
    node_info(Node, _, _).

%!  current_node(-Node) is det.
%
%   The node of the calling thread: the one set with node_set_current/1
%   (agent and worker threads have theirs), else the default node.
%
%   @error existence_error(platform, current) if no node runs.

current_node(Node) :-
    (   current_node_tl(N)
    ->  Node = N
    ;   default_node(N)
    ->  Node = N
    ;   existence_error(platform, current)
    ).

%!  node_set_current(+Node) is det.
%
%   Make Node the current node of the calling thread.

node_set_current(Node) :-
    must_be(atom, Node),
    (   node_info(Node, _, _)
    ->  true
    ;   existence_error(platform, Node)
    ),
    retractall(current_node_tl(_)),
    assertz(current_node_tl(Node)).

%!  node_clear_current is det.
%
%   Forget the current node of the calling thread: it falls back to the
%   process's default node. For threads that leave a node's work (agent
%   threads of the pool).

node_clear_current :-
    retractall(current_node_tl(_)).

%!  node_set_default(+Node) is det.
%
%   Make Node the process's default node.

node_set_default(Node) :-
    retractall(default_node(_)),
    assertz(default_node(Node)).

%!  with_node(+Node, :Goal)
%
%   Run Goal with Node as the current node of this thread.

with_node(Node, Goal) :-
    must_be(atom, Node),
    (   current_node_tl(Old)
    ->  true
    ;   Old = none
    ),
    setup_call_cleanup(
        node_set_current(Node),
        Goal,
        restore_current(Old)).

restore_current(none) :-
    !,
    retractall(current_node_tl(_)).
restore_current(Node) :-
    retractall(current_node_tl(_)),
    assertz(current_node_tl(Node)).

%!  registry_set_tokens(+Node, +Tokens) is det.
%
%   Replace the tokens of Node (node:node_set_tokens/2 checks them).

registry_set_tokens(Node, Tokens) :-
    retractall(node_tokens(Node, _)),
    assertz(node_tokens(Node, Tokens)).

%!  node_accepts(+Node, +ProofsNonce) is semidet.
%
%   True if one of Proofs (for Nonce) was made with one of Node's tokens,
%   or Node is open and the open key was proved.

node_accepts(Node, Proofs/Nonce) :-
    node_tokens(Node, Tokens0),
    (   Tokens0 == []
    ->  open_key(K),
        Tokens = [K]
    ;   Tokens = Tokens0
    ),
    member(T, Tokens),
    token_proof(T, Nonce, P),
    memberchk(P, Proofs),
    !.
%!  ctx_authorized(+Ctx) is semidet.
%
%   True if the peer may make requests that need authentication: it
%   proved a token, or the node is open (has no tokens: it accepts
%   anyone, see node_start/3).

ctx_authorized(Ctx) :-
    (   ctx_authenticated(Ctx)
    ->  true
    ;   ctx_node(Ctx, Node),
        node_tokens(Node, [])
    ).

