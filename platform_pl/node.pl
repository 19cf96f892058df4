:- module(node,
          [ node_start/3,               % +Address, -Node, +Options
            node_stop/1,                % +Node
            node_property/2,            % ?Node, ?Property
            current_node/1,             % -Node
            local_node/1,               % ?Node
            node_for_address/2,         % +Address, -Node
            node_set_current/1,         % +Node
            node_set_default/1,         % +Node
            node_set_tokens/2,          % +Node, +Tokens
            with_node/2,                % +Node, :Goal
            node_option/3,              % +Node, +Name, -Value
            node_accepts/2,             % +Node, +Proofs/Nonce
            node_listens_at/2,          % +Node, +Address
            node_is_self/2,             % +Node, +Address
            token_entropy_bits/2,       % +Token, -Bits
            node_clear_current/0,
            ctx_node/2,                 % +Ctx, -Node
            ctx_peer/2,                 % +Ctx, -Peer
            ctx_input/2,                % +Ctx, -InputStream
            ctx_authenticated/1,        % +Ctx
            ctx_authorized/1,           % +Ctx
            ctx_peer_name/2,            % +Ctx, -Name
            platform_shutdown/0
          ]).
:- use_module(transport, [address_normalize/2, transport_drop_pool/0]).
:- use_module(worker_pool, [pool_drain/0]).
:- use_module(tls, [tls_check_dir/1]).
:- use_module(node_id, [node_id_new/1, node_id_stored/2]).
:- use_module(node_admission, [admission_forget_node/1]).
:- use_module(node_connection, [connection_stop_all/1, connection_forget_node/1]).
:- use_module(node_registry,
              [ node_property/2, node_option/3, local_node/1, current_node/1,
                node_set_current/1, node_clear_current/0, node_set_default/1, with_node/2,
                registry_set_tokens/2, node_accepts/2, ctx_authorized/1,
                registry_add/2, registry_remove/1, registry_release_default/1,
                registry_bound/3 ]).
:- use_module(node_identity,
              [ node_for_address/2, node_listens_at/2, node_is_self/2, wildcard_host/1,
                advertised_address/4 ]).
:- use_module(node_acceptor, [acceptor_run/2, acceptor_stopping/1, acceptor_stopped/1]).
:- reexport(node_ctx,
            [ ctx_node/2, ctx_peer/2, ctx_input/2, ctx_authenticated/1, ctx_peer_name/2 ]).
:- use_module(secrets, [check_secrets/3, loopback_host/1, token_entropy_bits/2]).
:- autoload(library(socket),
            [ tcp_socket/1, tcp_setopt/2, tcp_bind/2, tcp_listen/2,
              tcp_accept/3, tcp_open_socket/2, tcp_close_socket/1,
              tcp_connect/3 ]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- autoload(library(option), [option/2, option/3, select_option/4]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [member/2, max_list/2]).
:- autoload(library(aggregate), [aggregate_all/3]).

/** <module> A platform node: listening socket, acceptor, connection workers

This module starts and stops nodes, keeps their identity and options,
and runs the acceptor. The rest of a node lives beside it: admission
and eviction of connections in node_admission.pl, the connection worker
(hello, frames, authentication) in node_connection.pl, request policy
and replies in node_request.pl, the connection context in node_ctx.pl
(its accessors re-exported here), ids in node_id.pl, the nodes' records,
options and current node in node_registry.pl, "is this address me?" in
node_identity.pl and the acceptor thread in node_acceptor.pl (their
public predicates re-exported here). None of them loads this module.

A node listens on the address it is given (and only there). An acceptor
thread takes connections and gives each to a worker thread, at most
max_connections at a time; a connection over that limit is told so and
closed. A worker greets the peer with hello(Version, Nonce, Info), then
reads frames with a size limit and an idle timeout, and answers each
request with ok(Result) or error(Error). A malformed frame gets an error
reply and the connection is closed; nothing a peer sends can stop the
node or block other connections. A connection on which the peer proved
a token may stay silent longer (auth_idle_timeout, default 60 s) than one
that did not (idle_timeout, 10 s): clients keep pooled connections alive
with pings. Requests are served by clauses of the
multifile hook node:platform_request/4, which the other platform modules
define. A clause receives the connection context Ctx, an opaque term
read with ctx_node/2, ctx_peer/2, ctx_input/2 and ctx_authenticated/1:

```
node:platform_request(ping_twice, Ctx, ok(pong(Node, Node)), true) :-
    ctx_node(Ctx, Node).
```

Several nodes may run in one process. Each thread has a current node: the
node an agent or worker thread belongs to, otherwise the process's
default node (the first started, or the one set with node_set_default/1).

Every node has an id, 32 hex digits, random or kept in `Dir/node_id` when
the node has store(Dir), so that a restarted node keeps it. The hello
carries it, and "is this address me?" (node_is_self/2) compares ids. A
node binds one address and advertises another (advertise(Host:Port);
by default the bind address, or the host name when it binds 0.0.0.0).
*/

:- dynamic
    node_acceptor/2.            % Node, ThreadId

:- multifile
    platform_request/4,         % +Request, +Ctx, -Reply, -After
    requires_authentication/1,  % +Request
    node_started/1,             % +Node
    node_stopping/1.            % +Node

:- predicate_options(node_start/3, 3,
                     [ token(any),
                       tokens(list),
                       max_connections(positive_integer),
                       idle_timeout(number),
                       auth_idle_timeout(number),
                       advertise(any),
                       store(any),
                       settle_period(number),
                       lease_s(number),
                       max_frame_size(positive_integer),
                       max_text_frame_size(positive_integer),
                       frame_deadline(number),
                       max_term_depth(positive_integer),
                       max_unauth_connections(positive_integer),
                       max_unauth_per_peer(positive_integer),
                       insecure(boolean),
                       tls(any),
                       tls_peers(list),
                       reply_timeout(number),
                       connect_timeout(number),
                       commit_timeout(number),
                       agent_cpu_limit(any),
                       agent_stack_limit(any),
                       agent_module_limit(any),
                       agent_post_limit(any),
                       agent_log_limit(any),
                       max_agents(any),
                       clone_limit(any),
                       agent_memory_budget(any),
                       max_running_agents(any),
                       agent_slot_wait(number),
                       agent_wall_limit(any),
                       agent_idle_limit(any),
                       max_agents_per_peer(any),
                       max_running_per_peer(any),
                       peer_post_limit(any),
                       default(boolean)
                     ]).

%!  node_start(+Address, -Node, +Options) is det.
%
%   Start a platform node listening on Address (Host:Port, (Host,Port) or
%   a port; port 0 lets the OS choose; host 0.0.0.0 binds every
%   interface). Node is the atom 'Host:Port' with the bind host and the
%   port actually bound. Options:
%
%     - token(+Token) / tokens(+List)
%       Tokens an arriving agent or privileged request must prove.
%       Without tokens the node is open: it accepts any agent.
%     - max_connections(+N)       concurrent connections (default 64)
%     - advertise(+Host:Port)     the address peers are told and reach
%                                 this node at (also advertise(Host): the
%                                 bound port). Default: the bind address,
%                                 with 0.0.0.0 replaced by the host name
%     - idle_timeout(+Sec)        idle time before a connection is
%                                 closed (default 10)
%     - auth_idle_timeout(+Sec)   the same once the peer proved a token
%                                 (default 60; pooled connections are
%                                 pinged well within it)
%     - store(+Dir)               keep state on disk in Dir (the node id
%                                 here; custody state by the hook
%                                 node_started/1). Default: memory only
%     - settle_period(+Sec), lease_s(+Sec) for the custody protocol
%                                 (defaults 2 and 10)
%     - max_frame_size(+Bytes)    largest frame from a peer that proved a
%                                 token (default 32 MiB: about 3 million
%                                 floats in a binary frame, 1.5 million as
%                                 text). Parsing a text frame takes 8 to 19
%                                 times its size (a string, a list of
%                                 small integers): two 32 MiB frames at
%                                 once raised a node's RSS by 481 and
%                                 1256 MiB (256 MiB frames: 2.8 GB)
%     - max_text_frame_size(+Bytes) largest frame before that (4096:
%                                 a hello is answered by auth(Proofs),
%                                 about 70 bytes a proof, and pings)
%     - frame_deadline(+Sec)      before a token proof, a whole frame must
%                                 arrive within Sec of its first byte
%                                 (default 5)
%     - max_term_depth(+D)        before a token proof, the deepest term
%                                 a frame may hold, and the deepest its
%                                 text may nest brackets (checked before
%                                 it is parsed; default 64). At most two
%                                 such frames over 512 bytes are parsed
%                                 at once in a process (flag
%                                 dfrl_preauth_parsers), so
%                                 unauthenticated peers cannot take every
%                                 core; an auth(Proofs) or a ping is
%                                 parsed at once, and authenticated
%                                 connections never wait for a slot
%     - max_unauth_connections(+N) connections that have not proved a
%                                 token, in total (default: half of
%                                 max_connections); the rest is kept for
%                                 authenticated peers
%     - max_unauth_per_peer(+N)   the same per peer address (default 16)
%     - reply_timeout(+Sec), connect_timeout(+Sec) for outgoing requests
%       (defaults 30 and 5)
%     - commit_timeout(+Sec)      how long a staged arriving agent waits
%                                 for its source to commit (default 10)
%     - default(+Bool)            make it the process's default node
%                                 (default: if there is none yet)
%     - insecure(+Bool)           start on a non-loopback address with a
%                                 weak token or none (default false)
%     - tls(+Dir)                 mutual TLS on every connection, in and
%                                 out, with the CA and certificate in Dir
%                                 (ca.crt, node.crt, node.key; see tls.pl):
%                                 peers without a certificate the CA
%                                 signed are refused
%     - tls_peers(+Names)         with tls(Dir): only peers whose
%                                 certificate's common name is in Names
%                                 may send agents or code (transfer,
%                                 commit, load_code, execute); others get
%                                 a permission error (default: any name
%                                 the CA signed)
%
%   Bounds on agents (agent_bounds.pl; each also takes `infinite`). An
%   agent over a per-call bound is stopped, removed and its sender told:
%
%     - agent_cpu_limit(+Sec)     CPU time of one handler call (default 2)
%     - agent_stack_limit(+Bytes) stacks of the thread running a handler
%                                 call (default 256 MiB)
%     - agent_module_limit(+Bytes) clauses in the agent's own module: its
%                                 code, payload and asserted facts
%                                 (default 64 MiB; also checked on arrival)
%     - agent_post_limit(+N)      posts an agent sends per minute
%                                 (default 600)
%     - agent_log_limit(+N)       lines of output per agent and minute
%                                 (default 200)
%     - max_agents(+N)            agents on the node; an arriving agent
%                                 over it is refused with
%                                 resource_error(agents) (default 100)
%     - clone_limit(+N)           clones arriving per minute; more are
%                                 refused with resource_error(clones)
%                                 (default 60)
%     - agent_memory_budget(+Bytes) what the node's agents may hold
%                                 together: their modules plus the stacks
%                                 of their running calls (default 1 GiB).
%                                 Over it the running call holding most
%                                 is stopped (memory_budget(Bytes)); an
%                                 arriving agent that does not fit is
%                                 refused with resource_error(agent_memory)
%     - max_running_agents(+N)    handler calls (main or posted event)
%                                 running at once; more wait for a slot,
%                                 then fail with
%                                 resource_error(running_agents) (the
%                                 agent stays, idle; default 8). With it,
%                                 the stacks of agents never exceed
%                                 N x agent_stack_limit
%     - agent_slot_wait(+Sec)     how long a call waits for one of those
%                                 slots (default 60)
%     - agent_wall_limit(+Sec)    wall time a handler call may hold a
%                                 slot (time parked with bounds_park/1
%                                 not counted); over it the call is
%                                 stopped with wall(Sec) (default 60)
%     - agent_idle_limit(+Sec)    an agent that arrived from a peer and
%                                 has not run (nor been parked) for Sec
%                                 is removed with idle(Sec); also the
%                                 most one call may stay parked
%                                 (default 600)
%     - max_agents_per_peer(+N)   agents one peer (its TLS certificate
%                                 name, else its IP address and claimed
%                                 node address) may have on the node
%                                 (default 50)
%     - max_running_per_peer(+N)  slots the calls of one peer's agents
%                                 may hold at once (default 4)
%     - peer_post_limit(+N)       posts one peer may deliver per minute;
%                                 more are refused with
%                                 resource_error(posts) (default 6000)
%
%   Secrets. A node bound to an address other than loopback (0.0.0.0
%   included) refuses to start if it is open or one of its tokens has
%   less than 128 bits of entropy (token_entropy_bits/2), unless told
%   insecure(true): its peers' proofs cross the network, and a weak
%   token falls to an offline search of one captured handshake. With
%   tls(Dir) they cross it encrypted, to a peer the CA vouches for, and
%   a weak token (or none) is accepted anywhere. On
%   loopback a weak token (a Tartarus-style integer) is accepted, with
%   an informational message.
%
%   Once the node listens, and before it accepts a connection, every
%   clause of the multifile hook node:node_started(+Node) is called with
%   Node as the current node (connections wait in the backlog until they
%   return; a hook that must talk to peers starts a thread). A hook that
%   raises an error stops the node and node_start/3 raises it:
%
%   ```
%   node:node_started(Node) :-
%       node_option(Node, store, Dir), Dir \== none,
%       my_recover(Node, Dir).
%   ```
%
%   @error domain_error(port, Port) for a port outside 0..65535.
%   @error socket_error(...) if the address cannot be bound.

node_start(Address0, Node, Options) :-
    address_normalize(Address0, Host:Port),
    must_be(list, Options),
    tokens_option(Options, Tokens),
    check_options(Options),
    check_secrets(Host:Port, Tokens, Options),
    (   option(store(Dir), Options)
    ->  node_id_stored(Dir, Id)
    ;   node_id_new(Id)
    ),
    tcp_socket(Socket),
    catch(( tcp_setopt(Socket, reuseaddr),
            bind_port(Socket, Host, Port, Bound),
            tcp_listen(Socket, 128)
          ),
          E,
          ( tcp_close_socket(Socket), throw(E) )),
    format(atom(Node), '~w:~w', [Host, Bound]),
    advertised_address(Options, Host, Bound, Advertised),
    get_time(Now),
    registry_add(Node, node(Host:Bound, Socket, Id, Advertised, Now, Tokens, Options)),
    (   option(default(true), Options)
    ->  node_set_default(Node)
    ;   option(default(false), Options)
    ->  true
    ;   node_property(_, default)
    ->  true
    ;   node_set_default(Node)
    ),
    catch(with_node(Node, forall(node_started(Node), true)), E2,
          ( catch(node_stop(Node), _, true), throw(E2) )),
    atom_concat('dfrl_acceptor@', Node, Alias),
    thread_create(acceptor_run(Node, Socket), Tid, [alias(Alias)]),
    assertz(node_acceptor(Node, Tid)),
    debug(dfrl(node), 'Node ~w started (id ~w, advertised as ~w)',
          [Node, Id, Advertised]).

check_options(Options) :-
    (   option(advertise(A), Options)
    ->  (   atomic(A)
        ->  true
        ;   address_normalize(A, _)
        )
    ;   true
    ),
    (   option(store(Dir), Options)
    ->  must_be(text, Dir)
    ;   true
    ),
    (   option(tls(TlsDir), Options)
    ->  tls_check_dir(TlsDir)
    ;   true
    ),
    (   option(tls_peers(Names), Options)
    ->  must_be(list(atom), Names),
        (   option(tls(_), Options)
        ->  true
        ;   throw(error(domain_error(tls_option, tls_peers(Names)),
                        context(node_start/3, 'tls_peers(Names) needs tls(Dir)')))
        )
    ;   true
    ),
    forall(( member(Name, [idle_timeout, auth_idle_timeout, commit_timeout,
                           settle_period, lease_s, reply_timeout,
                           connect_timeout, agent_slot_wait]),
             Opt =.. [Name, V],
             option(Opt, Options) ),
           must_be(number, V)),
    forall(( member(Name, [agent_cpu_limit, agent_stack_limit,
                           agent_module_limit, agent_post_limit,
                           agent_log_limit, max_agents, clone_limit,
                           agent_memory_budget, max_running_agents,
                           agent_wall_limit, agent_idle_limit,
                           max_agents_per_peer, max_running_per_peer,
                           peer_post_limit]),
             Opt =.. [Name, V],
             option(Opt, Options),
             V \== infinite ),
           (   memberchk(Name, [agent_cpu_limit, agent_wall_limit, agent_idle_limit])
           ->  must_be(number, V),
               (   V > 0 -> true ; must_be(positive_integer, V) )
           ;   must_be(positive_integer, V)
           )).

bind_port(Socket, Host, 0, Bound) :-
    !,
    tcp_bind(Socket, Host:Bound).
bind_port(Socket, Host, Port, Port) :-
    tcp_bind(Socket, Host:Port).

tokens_option(Options, Tokens) :-
    (   option(tokens(Tokens0), Options)
    ->  must_be(list, Tokens0)
    ;   option(token(T), Options)
    ->  Tokens0 = [T]
    ;   Tokens0 = []
    ),
    maplist(must_be(ground), Tokens0),
    Tokens = Tokens0.

%!  node_stop(+Node) is det.
%
%   Stop Node: its agents are stopped and forgotten (hook
%   node_stopping/1), open connections are closed, the acceptor is
%   joined and the socket released.
%
%   @error existence_error(platform, Node)

node_stop(Node) :-
    must_be(atom, Node),
    (   registry_bound(Node, Address, Socket)
    ->  true
    ;   existence_error(platform, Node)
    ),
    acceptor_stopping(Node),
    forall(node_stopping(Node), true),
    connection_stop_all(Node),
    (   node_acceptor(Node, _)
    ->  wake_acceptor(Address)
    ;   true
    ),
    (   retract(node_acceptor(Node, Tid))
    ->  catch(thread_join(Tid, _), _, true)
    ;   true
    ),
    catch(tcp_close_socket(Socket), _, true),
    registry_remove(Node),
    acceptor_stopped(Node),
    connection_forget_node(Node),
    admission_forget_node(Node),
    registry_release_default(Node),
    debug(dfrl(node), 'Node ~w stopped', [Node]).

wake_acceptor(Host0:Port) :-
    (   wildcard_host(Host0) -> Host = '127.0.0.1' ; Host = Host0 ),
    catch(setup_call_cleanup(
              tcp_connect(Host:Port, Pair, [bypass_proxy(true)]),
              true,
              close(Pair, [force(true)])),
          _, true).

:- at_halt(stop_all_nodes).

stop_all_nodes :-
    forall(registry_bound(Node, _, _), catch(node_stop(Node), _, true)).

		 /*******************************
		 *          BUILT-IN		*
		 *******************************/

platform_request(ping, Ctx, ok(pong(Node)), true) :-
    ctx_node(Ctx, Node).

%!  requires_authentication(+Request) is semidet.
%
%   Multifile hook: true if Request is served only to a peer that proved
%   one of the node's tokens (or to anyone by an open node). The
%   platform's own: listing and posting to agents, migration and custody
%   status, code loading, execution and transfers. A module serving its
%   own requests adds a clause, e.g.
%
%   ```
%   node:requires_authentication(my_status(_)).
%   ```

requires_authentication(post(_, _, _, _)).
requires_authentication(agents).
requires_authentication(migration_status(_)).
requires_authentication(custody_agents).
requires_authentication(load_code(_, _)).
requires_authentication(execute(_, _)).
requires_authentication(commit(_)).

%!  node_set_tokens(+Node, +Tokens) is det.
%
%   Replace the tokens of Node.

node_set_tokens(Node, Tokens) :-
    must_be(list, Tokens),
    maplist(must_be(ground), Tokens),
    registry_set_tokens(Node, Tokens).

%!  platform_shutdown is det.
%
%   Stop every node of this process, close pooled client connections and
%   let idle pool workers exit. For hosts that must end cleanly without
%   relying on signals (e.g. an embedded Prolog started with --nosignals).

platform_shutdown :-
    stop_all_nodes,
    transport_drop_pool,
    pool_drain.
