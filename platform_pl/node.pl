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
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(transport,
              [ address_normalize/2, token_proof/3, open_key/1,
                transport_drop_pool/0, transport_identify/3 ]).
:- use_module(worker_pool, [pool_run/3, pool_signal/3, pool_drain/0, pool_retire/0]).
:- use_module(tls, [tls_check_dir/1, tls_accept/5]).
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
:- autoload(library(crypto), [crypto_n_random_bytes/2]).
:- autoload(library(readutil), [read_file_to_string/3]).
:- autoload(library(filesex), [make_directory_path/1, directory_file_path/3]).

:- meta_predicate with_node(+, 0).

/** <module> A platform node: listening socket, acceptor, connection workers

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
    node_info/3,                % Node, Host:Port, ServerSocket
    node_ident/4,               % Node, Id, Advertised, StartedAt
    node_acceptor/2,            % Node, ThreadId
    node_tokens/2,              % Node, Tokens
    node_opt/2,                 % Node, Option
    default_node/1,             % Node
    stopping/1,                 % Node
    connection/3,               % Node, ConnId, ThreadId: a served connection
    conn_entry/5.               % Node, ConnId, PeerKey, Class, Since

:- thread_local
    serving/2.                  % Node, ConnId: this worker's connection

:- thread_local
    current_node_tl/1.

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
%                                 token (default 256 MiB)
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
    ->  stored_node_id(Dir, Id)
    ;   new_node_id(Id)
    ),
    tcp_socket(Socket),
    catch(( tcp_setopt(Socket, reuseaddr),
            bind_port(Socket, Host, Port, Bound),
            tcp_listen(Socket, 128)
          ),
          E,
          ( tcp_close_socket(Socket), throw(E) )),
    format(atom(Node), '~w:~w', [Host, Bound]),
    advertised(Options, Host, Bound, Advertised),
    get_time(Now),
    assertz(node_info(Node, Host:Bound, Socket)),
    assertz(node_ident(Node, Id, Advertised, Now)),
    assertz(node_tokens(Node, Tokens)),
    forall(member(O, Options), assertz(node_opt(Node, O))),
    (   option(default(true), Options)
    ->  node_set_default(Node)
    ;   option(default(false), Options)
    ->  true
    ;   default_node(_)
    ->  true
    ;   node_set_default(Node)
    ),
    catch(with_node(Node, forall(node_started(Node), true)), E2,
          ( catch(node_stop(Node), _, true), throw(E2) )),
    atom_concat('dfrl_acceptor@', Node, Alias),
    thread_create(accept_loop(Node, Socket), Tid, [alias(Alias)]),
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
                           connect_timeout]),
             Opt =.. [Name, V],
             option(Opt, Options) ),
           must_be(number, V)).

advertised(Options, Host, Bound, Advertised) :-
    (   option(advertise(A), Options)
    ->  (   atomic(A)
        ->  Advertised = A:Bound
        ;   address_normalize(A, AH:AP),
            (   AP =:= 0 -> Advertised = AH:Bound ; Advertised = AH:AP )
        )
    ;   wildcard_host(Host)
    ->  gethostname(Name),
        Advertised = Name:Bound
    ;   Advertised = Host:Bound
    ).

wildcard_host(H) :-
    atomic(H),
    atom_string(A, H),
    memberchk(A, ['0.0.0.0', '::', '']).

%   The node id: 32 hex digits from the crypto random generator, or the
%   one kept in Dir/node_id (written once: temporary file, then rename).
new_node_id(Id) :-
    crypto_n_random_bytes(16, Bytes),
    bytes_hex(Bytes, Id).

bytes_hex(Bytes, Hex) :-
    maplist([B, H]>>format(atom(H), '~|~`0t~16r~2+', [B]), Bytes, Hs),
    atomic_list_concat(Hs, Hex).

stored_node_id(Dir, Id) :-
    make_directory_path(Dir),
    directory_file_path(Dir, node_id, File),
    (   exists_file(File)
    ->  read_file_to_string(File, Text0, []),
        split_string(Text0, "", " \t\r\n", [Text]),
        (   string_length(Text, 32),
            string_codes(Text, Cs),
            forall(member(C, Cs), code_type(C, xdigit(_)))
        ->  atom_string(Id, Text)
        ;   throw(error(domain_error(node_id, Text), context(_, File)))
        )
    ;   new_node_id(Id),
        atom_concat(File, '.tmp', Tmp),
        setup_call_cleanup(open(Tmp, write, Out),
                           format(Out, "~w~n", [Id]),
                           close(Out)),
        rename_file(Tmp, File)
    ).

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
    (   node_info(Node, Address, Socket)
    ->  true
    ;   existence_error(platform, Node)
    ),
    assertz(stopping(Node)),
    forall(node_stopping(Node), true),
    forall(connection(Node, _, T),
           pool_signal(connections, T, node:stop_if_serving(Node))),
    (   node_acceptor(Node, _)
    ->  wake_acceptor(Address)
    ;   true
    ),
    (   retract(node_acceptor(Node, Tid))
    ->  catch(thread_join(Tid, _), _, true)
    ;   true
    ),
    catch(tcp_close_socket(Socket), _, true),
    retractall(node_info(Node, _, _)),
    retractall(node_ident(Node, _, _, _)),
    retractall(node_tokens(Node, _)),
    retractall(node_opt(Node, _)),
    retractall(stopping(Node)),
    retractall(connection(Node, _, _)),
    with_mutex(dfrl_conns, retractall(conn_entry(Node, _, _, _, _))),
    (   retract(default_node(Node))
    ->  (   node_info(Other, _, _)
        ->  assertz(default_node(Other))
        ;   true
        )
    ;   true
    ),
    retractall(current_node_tl(Node)),
    debug(dfrl(node), 'Node ~w stopped', [Node]).

wake_acceptor(Host0:Port) :-
    (   wildcard_host(Host0) -> Host = '127.0.0.1' ; Host = Host0 ),
    catch(setup_call_cleanup(
              tcp_connect(Host:Port, Pair, [bypass_proxy(true)]),
              true,
              close(Pair, [force(true)])),
          _, true).

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
option_default(max_frame_size, 268435456).
option_default(max_text_frame_size, 4096).
option_default(frame_deadline, 5).
option_default(max_term_depth, 64).
option_default(max_unauth_per_peer, 16).
option_default(reply_timeout, 30).
option_default(connect_timeout, 5).
option_default(commit_timeout, 10).
option_default(tls, none).
option_default(tls_peers, any).

%!  local_node(?Node) is nondet.
%
%   Node is a platform running in this process.

local_node(Node) :-
    node_info(Node, _, _).

%!  node_for_address(+Address, -Node) is semidet.
%
%   Node is the platform of this process that answers at Address, by
%   identity (see node_is_self/2). With Node unbound, at most one
%   connection is made to learn the id at Address.

node_for_address(Address, Node) :-
    nonvar(Node),
    !,
    node_is_self(Node, Address).
node_for_address(Address0, Node) :-
    address_normalize(Address0, Address),
    (   node_info(N, _, _),
        literal_self(N, Address)
    ->  Node = N
    ;   findall(T, node_ident(_, _, _, T), Starts),
        Starts \== [],
        max_list(Starts, Since),
        identify(Address, Since, Id),
        node_ident(N, Id, _, _)
    ->  Node = N
    ).

%!  node_listens_at(+Node, +Address) is semidet.
%
%   The same as node_is_self/2 (the name its callers know).

node_listens_at(Node, Address) :-
    node_is_self(Node, Address).

%!  node_is_self(+Node, +Address) is semidet.
%
%   True if Address (Host:Port, (Host,Port) or a port) reaches the
%   platform Node of this process. Decided by identity: the id in the
%   hello of the platform that answers at Address (from a pooled
%   connection, a hello seen there since Node started, or a new
%   connection, which stays pooled for the request that usually follows)
%   is Node's. Without a connection when Address is literally one Node
%   binds or advertises: the advertised address, or the bound port with
%   the bound host, another name of the loopback interface (`localhost`,
%   `127.0.0.1`), or, for a node bound to 0.0.0.0, a loopback name or the
%   host name. An address that cannot be reached is not Node.

node_is_self(Node, Address0) :-
    address_normalize(Address0, Address),
    node_ident(Node, Id, _, Started),
    (   literal_self(Node, Address)
    ->  true
    ;   identify(Address, Started, Id)
    ).

identify(Address, Since, Id) :-
    (   catch(current_node(Here), _, fail)
    ->  node_option(Here, connect_timeout, CT)
    ;   CT = 5
    ),
    catch(transport_identify(Address, Id0,
                             [since(Since), connect_timeout(CT),
                              reply_timeout(CT)]),
          E, ( debug(dfrl(node), 'identify ~w: ~p', [Address, E]), fail )),
    Id = Id0.

literal_self(Node, Host:Port) :-
    (   node_ident(Node, _, AH:AP, _),
        AP =:= Port,
        same_host(Host, AH)
    ->  true
    ;   node_info(Node, BH:BP, _),
        BP =:= Port,
        (   same_host(Host, BH)
        ->  true
        ;   wildcard_host(BH),
            (   loopback(Host)
            ->  true
            ;   gethostname(Name),
                same_host(Host, Name)
            )
        )
    ).

same_host(A, B) :-
    atomic(A), atomic(B),
    atom_string(A, S),
    atom_string(B, S),
    !.
same_host(A, B) :-
    loopback(A),
    loopback(B).

loopback(localhost).
loopback('127.0.0.1').
loopback("localhost").
loopback("127.0.0.1").

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

%!  node_set_tokens(+Node, +Tokens) is det.
%
%   Replace the tokens of Node.

node_set_tokens(Node, Tokens) :-
    must_be(list, Tokens),
    maplist(must_be(ground), Tokens),
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

:- at_halt(stop_all_nodes).

stop_all_nodes :-
    forall(node_info(Node, _, _), catch(node_stop(Node), _, true)).

		 /*******************************
		 *           ACCEPTOR		*
		 *******************************/

accept_loop(Node, Socket) :-
    catch(tcp_accept(Socket, Client, Peer), E, true),
    (   stopping(Node)
    ->  (   var(E) -> tcp_close_socket(Client) ; true )
    ;   nonvar(E)
    ->  print_message(warning, E),
        (   node_info(Node, _, _) -> accept_loop(Node, Socket) ; true )
    ;   dispatch(Node, Client, Peer),
        accept_loop(Node, Socket)
    ).

%   Admission. Every connection starts unauthenticated and becomes
%   authenticated when its peer proves a token (conn_entry/5 keeps its
%   class). Unauthenticated connections are capped per peer address and
%   in total, below max_connections, so the remaining slots are kept for
%   authenticated ones, which an unauthenticated flood never displaces.
%   At a cap, the new connection is not refused: the oldest
%   unauthenticated connection of the same peer (per-peer cap) or of the
%   peer holding the most (total cap) is evicted, so a trickling or
%   idle peer cannot keep a newcomer out, and a newcomer that proves its
%   token at once becomes authenticated before its turn comes. Only when
%   every slot is authenticated is a connection refused.
dispatch(Node, Client, Peer) :-
    peer_key(Peer, Key),
    flag(dfrl_conn_ids, CId, CId+1),
    get_time(Now),
    with_mutex(dfrl_conns, admit(Node, CId, Key, Now, Verdict)),
    (   Verdict = refuse
    ->  refuse_busy(Node, Client)
    ;   Verdict = evict(Victim)
    ->  evict(Node, Victim)
    ;   true
    ),
    (   Verdict == refuse
    ->  true
    ;   connection_workers_max(MaxWorkers),
        catch(pool_run(connections, serve_connection_job(Node, CId, Client, Peer),
                       [max(MaxWorkers)]),
              E, ( print_message(warning, E),
                   with_mutex(dfrl_conns, retractall(conn_entry(Node, CId, _, _, _))),
                   refuse_busy(Node, Client) ))
    ->  true
    ;   true
    ).

%   The connection pool (shared by the nodes of the process) holds twice
%   their connections: room for evicted workers that are still ending,
%   but not for a flood to grow it without bound.
connection_workers_max(Max) :-
    aggregate_all(sum(M), ( node_info(N, _, _), node_option(N, max_connections, M) ),
                  Sum),
    Max is max(16, 2 * Sum).

peer_key(ip(A,B,C,D), ip(A,B,C,D)) :- !.
peer_key(Peer, Peer).

admit(Node, CId, Key, Now, Verdict) :-
    node_option(Node, max_connections, Max),
    node_option(Node, max_unauth_connections, MaxU),
    node_option(Node, max_unauth_per_peer, MaxP),
    aggregate_all(count, conn_entry(Node, _, _, _, _), Total),
    aggregate_all(count, conn_entry(Node, _, _, unauth, _), Unauth),
    aggregate_all(count, conn_entry(Node, _, Key, unauth, _), Mine),
    (   Mine >= MaxP
    ->  oldest_unauth(Node, Key, Victim),
        Verdict = evict(Victim)
    ;   Unauth >= MaxU
    ->  busiest_peer(Node, Busiest),
        oldest_unauth(Node, Busiest, Victim),
        Verdict = evict(Victim)
    ;   Total >= Max
    ->  (   busiest_peer(Node, Busiest)
        ->  oldest_unauth(Node, Busiest, Victim),
            Verdict = evict(Victim)
        ;   Verdict = refuse
        )
    ;   Verdict = admit
    ),
    (   Verdict = evict(V)
    ->  retractall(conn_entry(Node, V, _, _, _))
    ;   true
    ),
    (   Verdict == refuse
    ->  true
    ;   assertz(conn_entry(Node, CId, Key, unauth, Now))
    ).

oldest_unauth(Node, Key, Victim) :-
    aggregate_all(min(Since, C), conn_entry(Node, C, Key, unauth, Since),
                  min(_, Victim)).

busiest_peer(Node, Key) :-
    findall(K, conn_entry(Node, _, K, unauth, _), Ks),
    Ks \== [],
    msort(Ks, Sorted),
    clumped_pairs(Sorted, Counts),
    aggregate_all(max(N, K), member(K-N, Counts), max(_, Key)).

clumped_pairs([], []).
clumped_pairs([K|Ks], [K-N|Rest]) :-
    take_same(K, Ks, 1, N, Ks1),
    clumped_pairs(Ks1, Rest).

take_same(K, [K1|Ks], N0, N, Rest) :-
    K1 == K,
    !,
    N1 is N0 + 1,
    take_same(K, Ks, N1, N, Rest).
take_same(_, Ks, N, N, Ks).

%   The victim's entry is gone already (it no longer counts); its worker,
%   if it runs, is told to close the connection. A worker that has not
%   recorded itself yet finds its entry gone when it starts (see
%   serve_connection/4: it records itself, then looks).
evict(Node, Victim) :-
    debug(dfrl(node), '~w: evicting unauthenticated connection ~w', [Node, Victim]),
    (   connection(Node, Victim, T)
    ->  pool_signal(connections, T, node:evict_if_serving(Node, Victim))
    ;   true
    ).

evict_if_serving(Node, CId) :-
    (   serving(Node, CId)
    ->  throw(dfrl_evicted)
    ;   true
    ).

%   A connection's class becomes authenticated (it no longer counts
%   against the unauthenticated caps).
mark_authenticated(Node) :-
    (   serving(Node, CId)
    ->  with_mutex(dfrl_conns,
                   (   retract(conn_entry(Node, CId, Key, _, Since))
                   ->  assertz(conn_entry(Node, CId, Key, auth, Since))
                   ;   true
                   ))
    ;   true
    ).

%   Signalled to a pooled worker when Node stops; harmless if the worker
%   has moved on to another job.
stop_if_serving(Node) :-
    thread_self(Me),
    (   connection(Node, _, Me)
    ->  throw(node_stopping)
    ;   true
    ).

%   A TLS node cannot say it in plaintext: it closes the connection.
refuse_busy(Node, Client) :-
    node_option(Node, tls, Dir),
    Dir \== none,
    !,
    catch(tcp_close_socket(Client), _, true).
refuse_busy(_, Client) :-
    catch(setup_call_cleanup(
              tcp_open_socket(Client, Pair),
              ( stream_pair(Pair, _, Out),
                set_stream(Out, type(binary)),
                frame_write(Out, text,
                            error(error(resource_error(connections), _)))
              ),
              close(Pair, [force(true)])),
          _, true).

		 /*******************************
		 *          CONNECTIONS		*
		 *******************************/

%   An eviction signal (evict/2) that lands after serve_connection/4 left
%   its catch but before it retracted serving/2 ends up here: finish the
%   clean-up it interrupted, quietly.
serve_connection_job(Node, CId, Client, Peer) :-
    catch(serve_connection(Node, CId, Client, Peer), dfrl_evicted,
          connection_cleanup(Node, CId, Client)).

connection_cleanup(Node, CId, Client) :-
    catch(tcp_close_socket(Client), _, true),
    with_mutex(dfrl_conns, retractall(conn_entry(Node, CId, _, _, _))),
    retractall(serving(_, _)),
    retractall(connection(Node, CId, _)),
    retractall(current_node_tl(_)).

serve_connection(Node, CId, Client, Peer) :-
    thread_self(Me),
    assertz(connection(Node, CId, Me)),
    assertz(serving(Node, CId)),
    catch(setup_call_cleanup(
              ( node_set_current_if_alive(Node),
                (   conn_entry(Node, CId, _, _, _)
                ->  true
                ;   throw(dfrl_evicted)          % evicted before it began
                ),
                catch(tcp_setopt(Client, nodelay), _, true),
                tcp_open_socket(Client, Pair)
              ),
              serve_pair(Node, Pair, Peer),
              close(Pair, [force(true)])),
          E,
          connection_ended(Node, Peer, E)),
    (   var(Pair)
    ->  catch(tcp_close_socket(Client), _, true)
    ;   true
    ),
    with_mutex(dfrl_conns, retractall(conn_entry(Node, CId, _, _, _))),
    retractall(serving(_, _)),
    retractall(connection(Node, CId, Me)),
    retractall(current_node_tl(_)).

%   After a rejected frame: give its memory back. A reader that ran out of
%   C stack leaves the pages it touched resident in this thread (no trim
%   returns them), so its worker exits when the connection ends.
rejected_frame(Reason) :-
    (   Reason = syntax(resource_error(_))
    ->  pool_retire
    ;   true
    ),
    release_memory.

%   The parse slots of unauthenticated frames (see frame_read/3): a
%   message queue holding as many `slot` messages as the flag
%   dfrl_preauth_parsers (2) says, one queue per process, made once.
:- create_prolog_flag(dfrl_preauth_parsers, 2, [type(integer), keep(true)]).

preauth_parse_slots(Q) :-
    Q = dfrl_preauth_parse,
    (   catch(message_queue_property(Q, size(_)), _, fail)
    ->  true
    ;   with_mutex(dfrl_conns,
                   (   catch(message_queue_property(Q, size(_)), _, fail)
                   ->  true
                   ;   current_prolog_flag(dfrl_preauth_parsers, N),
                       message_queue_create(Q, [alias(Q)]),
                       forall(between(1, N, _), thread_send_message(Q, slot))
                   ))
    ).

%   Give back what a large or rejected frame made the worker's stacks grow
%   to (a worker thread is reused, and a hostile frame must not leave its
%   memory behind): collect, shrink the stacks, and hand freed memory back
%   to the OS (trim_heap/0; tcmalloc otherwise keeps it).
release_memory :-
    garbage_collect,
    trim_stacks,
    catch(trim_heap, _, true).

node_set_current_if_alive(Node) :-
    (   node_info(Node, _, _)
    ->  node_set_current(Node)
    ;   throw(node_stopping)
    ).

connection_ended(_, _, node_stopping) :- !.
connection_ended(_, _, dfrl_evicted) :- !.
connection_ended(_, _, '$aborted') :- !.
connection_ended(_, _, unwind(_)) :- !.
connection_ended(_, _, error(existence_error(platform, _), _)) :- !.
connection_ended(_, _, error(timeout_error(_, _), _)) :- !.
connection_ended(_, _, error(io_error(_, _), _)) :- !.
connection_ended(_, _, error(socket_error(_, _), _)) :- !.
connection_ended(_, _, error(ssl_error(_, _, _, _), _)) :- !.  % TLS peer gone
connection_ended(Node, Peer, error(tls_error(_, Reason), _)) :-
    !,
    debug(dfrl(node), '~w: TLS refused ~p: ~w', [Node, Peer, Reason]).
connection_ended(Node, Peer, E) :-
    print_message(warning, dfrl(connection_error(Node, Peer, E))).

%   A TLS node first runs the handshake, under the pre-authentication
%   frame deadline; the encrypted pair is closed before the plain one.
serve_pair(Node, Plain, Peer) :-
    node_option(Node, tls, Dir),
    Dir \== none,
    !,
    node_option(Node, frame_deadline, Deadline),
    tls_accept(Dir, Plain, Pair, PeerName, [deadline(Deadline)]),
    setup_call_cleanup(true,
                       serve_stream(Node, Pair, Peer, PeerName),
                       close(Pair, [force(true)])).
serve_pair(Node, Pair, Peer) :-
    serve_stream(Node, Pair, Peer, none).

serve_stream(Node, Pair, Peer, PeerName) :-
    stream_pair(Pair, In, Out),
    set_stream(In, type(binary)),
    set_stream(Out, type(binary)),
    node_option(Node, idle_timeout, Idle),
    set_stream(In, timeout(Idle)),
    random_nonce(Nonce),
    node_ident(Node, Id, Host:Port, _),
    node_option(Node, auth_idle_timeout, AuthIdle),
    wire_version(V),
    frame_write(Out, text,
                hello(V, Nonce, node(Host, Port, [id(Id), idle(Idle),
                                                  auth_idle(AuthIdle)]))),
    Ctx = ctx(Node, Peer, Nonce, In, Out, _Authenticated, PeerName),
    serve_frames(Ctx).

random_nonce(Nonce) :-
    new_node_id(Nonce).

%   The idle limit is set before every frame: a request's After goal may
%   have changed the stream's timeout (a staged migration waits for its
%   commit with the commit timeout).
serve_frames(Ctx) :-
    Ctx = ctx(Node, _, _, In, Out, Auth, _),
    (   Auth == true
    ->  node_option(Node, max_frame_size, Max),
        node_option(Node, auth_idle_timeout, Idle),
        ReadOptions = [max_size(Max), binary(true)]
    ;   node_option(Node, max_text_frame_size, Max),
        node_option(Node, idle_timeout, Idle),
        node_option(Node, frame_deadline, Deadline),
        node_option(Node, max_term_depth, Depth),
        preauth_parse_slots(Slots),
        ReadOptions = [ max_size(Max), binary(false), deadline(Deadline),
                        max_depth(Depth), parse_slots(Slots, 512) ]
    ),
    set_stream(In, timeout(Idle)),
    byte_count(In, Before),
    catch(frame_read(In, Frame, ReadOptions),
          error(wire_error(Reason), _),
          ( reply(Out, error(error(wire_error(Reason), _))),
            Frame = end_of_file,
            rejected_frame(Reason)
          )),
    (   Frame == end_of_file
    ->  true
    ;   Frame = frame(_, Term),
        serve_term(Term, Ctx, Continue),
        byte_count(In, After),
        (   After - Before > 4194304
        ->  release_memory
        ;   true
        ),
        (   Continue == true
        ->  serve_frames(Ctx)
        ;   true
        )
    ).

serve_term(auth(Proofs), Ctx, true) :-
    !,
    Ctx = ctx(Node, _, Nonce, _, Out, Auth, _),
    (   is_list(Proofs),
        node_accepts(Node, Proofs/Nonce)
    ->  nb_setarg(6, Ctx, true),
        mark_authenticated(Node),
        reply(Out, ok(authenticated))
    ;   (   var(Auth)
        ->  nb_setarg(6, Ctx, false)
        ;   true
        ),
        node_ident(Node, _, Here, _),
        reply(Out, error(error(permission_error(authenticate, platform, Here), _)))
    ).
serve_term(Request, Ctx, Continue) :-
    Ctx = ctx(Node, Peer, _, _, Out, _, _),
    debug(dfrl(request), '~w: ~p from ~p', [Node, Request, Peer]),
    catch(handle(Request, Ctx, Reply, After), E,
          ( Reply = error(E), After = true )),
    (   Reply == none
    ->  true
    ;   reply(Out, Reply)
    ),
    (   After == close
    ->  Continue = false
    ;   After == true
    ->  Continue = true
    ;   After = continue(Goal)
    ->  catch(( Goal -> Continue = true ; Continue = false ), E2,
              after_failed(E2, Continue))
    ;   catch(After, E2, print_message(warning, E2)),
        Continue = false
    ).

after_failed(connection_lost, false) :- !.
after_failed('$aborted', _) :- !, throw('$aborted').
after_failed(E, false) :-
    print_message(warning, E).

handle(Request, Ctx, Reply, After) :-
    (   \+ callable(Request)
    ->  unknown_request(Request, Reply),
        After = true
    ;   requires_authentication(Request),
        \+ ctx_authorized(Ctx)
    ->  ctx_node(Ctx, Node),
        node_ident(Node, _, Here, _),
        functor(Request, Name, Arity),
        Reply = error(error(permission_error(request, platform, Here),
                            context(Name/Arity,
                                    'this request needs a proved token'))),
        After = true
    ;   restricted_to_tls_peers(Request),
        \+ tls_peer_allowed(Ctx)
    ->  ctx_node(Ctx, Node),
        node_ident(Node, _, Here, _),
        functor(Request, Name, Arity),
        (   ctx_peer_name(Ctx, Peer) -> true ; Peer = none ),
        Reply = error(error(permission_error(request, platform, Here),
                            context(Name/Arity, not_in_tls_peers(Peer)))),
        After = true
    ;   platform_request(Request, Ctx, Reply0, After0)
    ->  Reply = Reply0,
        After = After0
    ;   unknown_request(Request, Reply),
        After = true
    ).

%   An unknown request is answered with its name and arity only: the
%   request itself may be large (and echoing it back is the peer's
%   work, not ours).
unknown_request(Request, error(error(domain_error(platform_request, What), _))) :-
    (   callable(Request)
    ->  functor(Request, Name, Arity),
        What = Name/Arity
    ;   What = not_callable
    ).

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

%   Requests that send an agent or code: with tls_peers(Names), only
%   from a peer whose certificate names one of Names.
restricted_to_tls_peers(transfer(_, _, _, _, _)).
restricted_to_tls_peers(transfer(_, _, _, _, _, _)).
restricted_to_tls_peers(commit(_)).
restricted_to_tls_peers(load_code(_, _)).
restricted_to_tls_peers(execute(_, _)).

tls_peer_allowed(Ctx) :-
    ctx_node(Ctx, Node),
    node_option(Node, tls_peers, Names),
    (   Names == any
    ->  true
    ;   ctx_peer_name(Ctx, Name),
        memberchk(Name, Names)
    ).

reply(Out, Reply) :-
    sanitize_reply(Reply, Safe),
    frame_write(Out, text, Safe).

%   Error contexts may hold streams, clause references or other blobs
%   that cannot be written and read back: send the formal only.
sanitize_reply(error(E), error(error(Safe, _))) :-
    !,
    (   E = error(Formal, _)
    ->  true
    ;   Formal = E
    ),
    (   writable_term(Formal)
    ->  Safe = Formal
    ;   format(string(Text), '~p', [Formal]),
        Safe = remote_failure(Text)
    ).
sanitize_reply(Reply, Reply).

%   Linear in the size of T (sub_term/2 is quadratic on deep terms: a
%   reply echoing a 200 KB operator chain took a minute of CPU).
writable_term(T) :-
    (   compound(T)
    ->  compound_name_arity(T, _, A),
        writable_args(1, A, T)
    ;   blob(T, Type)
    ->  memberchk(Type, [text, reserved_symbol])
    ;   true
    ).

writable_args(I, A, _) :-
    I > A,
    !.
writable_args(I, A, T) :-
    arg(I, T, X),
    writable_term(X),
    I1 is I + 1,
    writable_args(I1, A, T).

		 /*******************************
		 *       CONNECTION CONTEXT	*
		 *******************************/

%   The context of a served connection: ctx(Node, Peer, Nonce, In, Out,
%   Authenticated, PeerName), where PeerName is the CN of the peer's
%   verified certificate or `none`, and Authenticated is unbound until the peer sent
%   auth(Proofs), then true or false (set destructively by serve_term/3).
%   Other modules read it through the accessors below only.

%!  ctx_node(+Ctx, -Node) is det.
%
%   Node is the platform that serves the connection.

ctx_node(ctx(Node, _, _, _, _, _, _), Node).

%!  ctx_peer(+Ctx, -Peer) is det.
%
%   Peer is the peer's address as tcp_accept/3 gave it.

ctx_peer(ctx(_, Peer, _, _, _, _, _), Peer).

%!  ctx_input(+Ctx, -In) is det.
%
%   In is the binary input stream of the connection (for a request that
%   reads further frames after its reply, as a staged migration does).

ctx_input(ctx(_, _, _, In, _, _, _), In).

%!  ctx_authenticated(+Ctx) is semidet.
%
%   True if the peer proved one of the node's tokens on this connection.

ctx_authenticated(ctx(_, _, _, _, _, Auth, _)) :-
    Auth == true.

%!  ctx_peer_name(+Ctx, -Name) is semidet.
%
%   Name (an atom) is the common name of the certificate the peer
%   presented on this connection, verified against the node's CA (see
%   the tls(Dir) option of node_start/3). Fails on a plaintext
%   connection.

ctx_peer_name(ctx(_, _, _, _, _, _, Name), Name) :-
    atom(Name),
    Name \== none.

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

		 /*******************************
		 *          BUILT-IN		*
		 *******************************/

platform_request(ping, Ctx, ok(pong(Node)), true) :-
    ctx_node(Ctx, Node).

%!  platform_shutdown is det.
%
%   Stop every node of this process, close pooled client connections and
%   let idle pool workers exit. For hosts that must end cleanly without
%   relying on signals (e.g. an embedded Prolog started with --nosignals).

platform_shutdown :-
    stop_all_nodes,
    transport_drop_pool,
    pool_drain.
