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
            node_clear_current/0,
            ctx_node/2,                 % +Ctx, -Node
            ctx_peer/2,                 % +Ctx, -Peer
            ctx_input/2,                % +Ctx, -InputStream
            ctx_authenticated/1,        % +Ctx
            platform_shutdown/0
          ]).
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(transport,
              [address_normalize/2, token_proof/3, open_key/1, transport_drop_pool/0]).
:- use_module(worker_pool, [pool_run/3, pool_signal/3, pool_drain/0]).
:- autoload(library(socket),
            [ tcp_socket/1, tcp_setopt/2, tcp_bind/2, tcp_listen/2,
              tcp_accept/3, tcp_open_socket/2, tcp_close_socket/1,
              tcp_connect/3 ]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- autoload(library(option), [option/2, option/3, select_option/4]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [member/2]).

:- meta_predicate with_node(+, 0).

/** <module> A platform node: listening socket, acceptor, connection workers

A node listens on the address it is given (and only there). An acceptor
thread takes connections and gives each to a worker thread, at most
max_connections at a time; a connection over that limit is told so and
closed. A worker greets the peer with hello(Version, Nonce, Info), then
reads frames with a size limit and an idle timeout, and answers each
request with ok(Result) or error(Error). A malformed frame gets an error
reply and the connection is closed; nothing a peer sends can stop the
node or block other connections. Requests are served by clauses of the
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
*/

:- dynamic
    node_info/3,                % Node, Host:Port, ServerSocket
    node_acceptor/2,            % Node, ThreadId
    node_tokens/2,              % Node, Tokens
    node_opt/2,                 % Node, Option
    default_node/1,             % Node
    stopping/1,                 % Node
    connection/2.               % Node, ThreadId

:- thread_local
    current_node_tl/1.

:- multifile
    platform_request/4,         % +Request, +Ctx, -Reply, -After
    node_stopping/1.            % +Node

:- predicate_options(node_start/3, 3,
                     [ token(any),
                       tokens(list),
                       max_connections(positive_integer),
                       idle_timeout(number),
                       max_frame_size(positive_integer),
                       max_text_frame_size(positive_integer),
                       reply_timeout(number),
                       connect_timeout(number),
                       commit_timeout(number),
                       default(boolean)
                     ]).

%!  node_start(+Address, -Node, +Options) is det.
%
%   Start a platform node listening on Address (Host:Port, (Host,Port) or
%   a port; port 0 lets the OS choose). Node is the atom 'Host:Port' with
%   the port actually bound. Options:
%
%     - token(+Token) / tokens(+List)
%       Tokens an arriving agent or privileged request must prove.
%       Without tokens the node is open: it accepts any agent.
%     - max_connections(+N)       concurrent connections (default 64)
%     - idle_timeout(+Sec)        idle time before a connection is
%                                 closed (default 10)
%     - max_frame_size(+Bytes)    largest frame from a peer that proved a
%                                 token (default 256 MiB)
%     - max_text_frame_size(+Bytes) largest frame before that (1 MiB)
%     - reply_timeout(+Sec), connect_timeout(+Sec) for outgoing requests
%       (defaults 30 and 5)
%     - commit_timeout(+Sec)      how long a staged arriving agent waits
%                                 for its source to commit (default 10)
%     - default(+Bool)            make it the process's default node
%                                 (default: if there is none yet)
%
%   @error domain_error(port, Port) for a port outside 0..65535.
%   @error socket_error(...) if the address cannot be bound.

node_start(Address0, Node, Options) :-
    address_normalize(Address0, Host:Port),
    must_be(list, Options),
    tokens_option(Options, Tokens),
    tcp_socket(Socket),
    catch(( tcp_setopt(Socket, reuseaddr),
            bind_port(Socket, Host, Port, Bound),
            tcp_listen(Socket, 128)
          ),
          E,
          ( tcp_close_socket(Socket), throw(E) )),
    format(atom(Node), '~w:~w', [Host, Bound]),
    assertz(node_info(Node, Host:Bound, Socket)),
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
    atom_concat('dfrl_acceptor@', Node, Alias),
    thread_create(accept_loop(Node, Socket), Tid, [alias(Alias)]),
    assertz(node_acceptor(Node, Tid)),
    debug(dfrl(node), 'Node ~w started', [Node]).

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
    forall(connection(Node, T),
           pool_signal(connections, T, node:stop_if_serving(Node))),
    wake_acceptor(Address),
    (   retract(node_acceptor(Node, Tid))
    ->  catch(thread_join(Tid, _), _, true)
    ;   true
    ),
    catch(tcp_close_socket(Socket), _, true),
    retractall(node_info(Node, _, _)),
    retractall(node_tokens(Node, _)),
    retractall(node_opt(Node, _)),
    retractall(stopping(Node)),
    retractall(connection(Node, _)),
    (   retract(default_node(Node))
    ->  (   node_info(Other, _, _)
        ->  assertz(default_node(Other))
        ;   true
        )
    ;   true
    ),
    retractall(current_node_tl(Node)),
    debug(dfrl(node), 'Node ~w stopped', [Node]).

wake_acceptor(Host:Port) :-
    catch(setup_call_cleanup(
              tcp_connect(Host:Port, Pair, [bypass_proxy(true)]),
              true,
              close(Pair, [force(true)])),
          _, true).

%!  node_property(?Node, ?Property) is nondet.
%
%   Properties: address(Host:Port), link((Host,Port)), tokens(List),
%   default (if it is the process's default node), option(Option).

node_property(Node, Property) :-
    node_info(Node, Address, _),
    node_property_(Property, Node, Address).

node_property_(address(Address), _, Address).
node_property_(link((H,P)), _, H:P).
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
    ;   option_default(Name, Value)
    ).

option_default(max_connections, 64).
option_default(idle_timeout, 10).
option_default(max_frame_size, 268435456).
option_default(max_text_frame_size, 1048576).
option_default(reply_timeout, 30).
option_default(connect_timeout, 5).
option_default(commit_timeout, 10).

%!  local_node(?Node) is nondet.
%
%   Node is a platform running in this process.

local_node(Node) :-
    node_info(Node, _, _).

%!  node_for_address(+Address, -Node) is semidet.
%
%   Node is the platform of this process listening on Address.

node_for_address(Address, Node) :-
    node_info(Node, _, _),
    node_listens_at(Node, Address),
    !.

%!  node_listens_at(+Node, +Address) is semidet.
%
%   True if Address (Host:Port, (Host,Port) or a port) reaches the
%   platform Node of this process: the same port, and the same host
%   name or two names of the loopback interface (`localhost`,
%   `127.0.0.1`). This is the one test of "is this address that node";
%   it compares address text, so it does not know that another name of
%   this host also reaches it.

node_listens_at(Node, Address0) :-
    address_normalize(Address0, Host:Port),
    node_info(Node, H:P, _),
    P =:= Port,
    same_host(Host, H).

same_host(H, H) :- !.
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

dispatch(Node, Client, Peer) :-
    node_option(Node, max_connections, Max),
    aggregate_all(count, connection(Node, _), Open),
    (   Open >= Max
    ->  refuse_busy(Client)
    ;   catch(pool_run(connections, serve_connection(Node, Client, Peer),
                       [max(10000)]),
              E, (print_message(warning, E), refuse_busy(Client)))
    ->  true
    ;   true
    ).

%   Signalled to a pooled worker when Node stops; harmless if the worker
%   has moved on to another job.
stop_if_serving(Node) :-
    thread_self(Me),
    (   connection(Node, Me)
    ->  throw(node_stopping)
    ;   true
    ).

refuse_busy(Client) :-
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

serve_connection(Node, Client, Peer) :-
    thread_self(Me),
    assertz(connection(Node, Me)),
    catch(setup_call_cleanup(
              ( node_set_current_if_alive(Node),
                catch(tcp_setopt(Client, nodelay), _, true),
                tcp_open_socket(Client, Pair)
              ),
              serve_pair(Node, Pair, Peer),
              close(Pair, [force(true)])),
          E,
          connection_ended(Node, Peer, E)),
    retractall(connection(Node, Me)),
    retractall(current_node_tl(_)).

node_set_current_if_alive(Node) :-
    (   node_info(Node, _, _)
    ->  node_set_current(Node)
    ;   throw(node_stopping)
    ).

connection_ended(_, _, node_stopping) :- !.
connection_ended(_, _, '$aborted') :- !.
connection_ended(_, _, unwind(_)) :- !.
connection_ended(_, _, error(existence_error(platform, _), _)) :- !.
connection_ended(_, _, error(timeout_error(_, _), _)) :- !.
connection_ended(_, _, error(io_error(_, _), _)) :- !.
connection_ended(_, _, error(socket_error(_, _), _)) :- !.
connection_ended(Node, Peer, E) :-
    print_message(warning, dfrl(connection_error(Node, Peer, E))).

serve_pair(Node, Pair, Peer) :-
    stream_pair(Pair, In, Out),
    set_stream(In, type(binary)),
    set_stream(Out, type(binary)),
    node_option(Node, idle_timeout, Idle),
    set_stream(In, timeout(Idle)),
    random_nonce(Nonce),
    node_info(Node, Host:Port, _),
    wire_version(V),
    frame_write(Out, text, hello(V, Nonce, node(Host, Port))),
    Ctx = ctx(Node, Peer, Nonce, In, Out, _Authenticated),
    serve_frames(Ctx).

random_nonce(Nonce) :-
    length(Bytes, 16),
    maplist([B]>>random_between(0, 255, B), Bytes),
    format(atom(Nonce), '~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+\c
                         ~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+\c
                         ~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+\c
                         ~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+~|~`0t~16r~2+',
           Bytes).

serve_frames(Ctx) :-
    Ctx = ctx(Node, _, _, In, Out, Auth),
    (   Auth == true
    ->  node_option(Node, max_frame_size, Max),
        Binary = true
    ;   node_option(Node, max_text_frame_size, Max),
        Binary = false
    ),
    catch(frame_read(In, Frame, [max_size(Max), binary(Binary)]),
          error(wire_error(Reason), _),
          ( reply(Out, error(error(wire_error(Reason), _))),
            Frame = end_of_file
          )),
    (   Frame == end_of_file
    ->  true
    ;   Frame = frame(_, Term),
        serve_term(Term, Ctx, Continue),
        (   Continue == true
        ->  serve_frames(Ctx)
        ;   true
        )
    ).

serve_term(auth(Proofs), Ctx, true) :-
    !,
    Ctx = ctx(Node, _, Nonce, _, Out, Auth),
    (   is_list(Proofs),
        node_accepts(Node, Proofs/Nonce)
    ->  nb_setarg(6, Ctx, true),
        reply(Out, ok(authenticated))
    ;   (   var(Auth)
        ->  nb_setarg(6, Ctx, false)
        ;   true
        ),
        node_info(Node, Here, _),
        reply(Out, error(error(permission_error(authenticate, platform, Here), _)))
    ).
serve_term(Request, Ctx, Continue) :-
    Ctx = ctx(Node, Peer, _, _, Out, _),
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
    (   platform_request(Request, Ctx, Reply0, After0)
    ->  Reply = Reply0,
        After = After0
    ;   Reply = error(error(domain_error(platform_request, Request), _)),
        After = true
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

writable_term(T) :-
    \+ ( sub_term(S, T), blob(S, Type), \+ memberchk(Type, [text, reserved_symbol]) ).

		 /*******************************
		 *       CONNECTION CONTEXT	*
		 *******************************/

%   The context of a served connection: ctx(Node, Peer, Nonce, In, Out,
%   Authenticated), where Authenticated is unbound until the peer sent
%   auth(Proofs), then true or false (set destructively by serve_term/3).
%   Other modules read it through the accessors below only.

%!  ctx_node(+Ctx, -Node) is det.
%
%   Node is the platform that serves the connection.

ctx_node(ctx(Node, _, _, _, _, _), Node).

%!  ctx_peer(+Ctx, -Peer) is det.
%
%   Peer is the peer's address as tcp_accept/3 gave it.

ctx_peer(ctx(_, Peer, _, _, _, _), Peer).

%!  ctx_input(+Ctx, -In) is det.
%
%   In is the binary input stream of the connection (for a request that
%   reads further frames after its reply, as a staged migration does).

ctx_input(ctx(_, _, _, In, _, _), In).

%!  ctx_authenticated(+Ctx) is semidet.
%
%   True if the peer proved one of the node's tokens on this connection.

ctx_authenticated(ctx(_, _, _, _, _, Auth)) :-
    Auth == true.

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
