:- module(node_connection,
          [ connection_serve/4,         % +Node, +ConnId, +Socket, +Peer
            connection_evict/2,         % +Node, +ConnId
            connection_stop_all/1,      % +Node
            connection_forget_node/1    % +Node
          ]).
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(worker_pool, [pool_signal/3, pool_retire/0]).
:- use_module(tls, [tls_accept/5]).
:- use_module(node_id, [node_id_new/1]).
:- use_module(node_ctx,
              [ ctx_new/7, ctx_node/2, ctx_peer/2, ctx_input/2, ctx_output/2,
                ctx_nonce/2, ctx_authenticated/1, ctx_set_authenticated/2 ]).
:- use_module(node_admission,
              [ admission_holds/2, admission_authenticated/2, admission_forget/2 ]).
:- use_module(node_request, [request_handle/4, request_reply/2]).
:- use_module(node_registry,
              [ node_option/3, node_property/2, node_accepts/2, local_node/1,
                node_set_current/1, node_clear_current/0 ]).
%   Libraries are imported eagerly here (use_module/2, not autoload/2),
%   as in every module that runs in connection workers (tls, wire,
%   transport, worker_pool): a worker is signalled (evicted, stopped)
%   at any moment, and a signal that lands while it autoloads a library
%   left the predicate undefined for the other workers too ("Unknown
%   procedure tls:option/3" under a burst of stalled handshakes).
:- use_module(library(socket), [tcp_setopt/2, tcp_open_socket/2, tcp_close_socket/1]).
:- use_module(library(debug), [debug/3]).
:- use_module(hop_probe, [hop_probe/1]).      % compiled away unless benchmarking

/** <module> A node's connection worker: hello, frames, authentication

Each connection a node admits is served by a worker of the process's
`connections` pool. The worker greets the peer with hello(Version,
Nonce, Info), where Info carries the node's advertised address, its id
and its idle limits, then reads frames until the peer leaves, the idle
limit passes, or the node stops or evicts the connection. Before the
peer proved a token a frame is read under tight limits (size, a
whole-frame deadline, nesting depth, a parse slot: see frame_read/3);
after, under the node's max_frame_size. auth(Proofs) is served here;
every other request by node_request.pl. A TLS node runs the handshake
first, under the pre-authentication frame deadline.

A worker is reused for other connections, so what a hostile frame made
its stacks grow to is given back, and a worker whose reader ran out of
C stack retires when its connection ends.
*/

:- dynamic
    connection/3.               % Node, ConnId, ThreadId: a served connection

:- thread_local
    serving/2.                  % Node, ConnId: this worker's connection

%!  connection_serve(+Node, +ConnId, +Socket, +Peer) is det.
%
%   Serve the accepted Socket of Node from Peer as connection ConnId
%   (admitted by node_admission.pl) until it ends; the socket is closed
%   and the connection forgotten whatever happens. Run by a pool worker.

%   An eviction signal (connection_evict/2) that lands after
%   serve_connection/4 left its catch but before it retracted serving/2
%   ends up here: finish the clean-up it interrupted, quietly.
connection_serve(Node, CId, Client, Peer) :-
    catch(serve_connection(Node, CId, Client, Peer), dfrl_evicted,
          connection_cleanup(Node, CId, Client)).

connection_cleanup(Node, CId, Client) :-
    catch(tcp_close_socket(Client), _, true),
    admission_forget(Node, CId),
    retractall(serving(_, _)),
    retractall(connection(Node, CId, _)),
    node_clear_current.

serve_connection(Node, CId, Client, Peer) :-
    thread_self(Me),
    assertz(connection(Node, CId, Me)),
    assertz(serving(Node, CId)),
    catch(setup_call_cleanup(
              ( node_set_current_if_alive(Node),
                (   admission_holds(Node, CId)
                ->  true
                ;   throw(dfrl_evicted)          % evicted before it began
                ),
                catch(tcp_setopt(Client, nodelay), _, true),
                tcp_open_socket(Client, Pair)
              ),
              serve_pair(Node, Pair, Peer),
              close(Pair, [force(true)])),
          E,
          true),
    (   var(Pair)
    ->  catch(tcp_close_socket(Client), _, true)
    ;   true
    ),
    admission_forget(Node, CId),
    retractall(serving(_, _)),
    retractall(connection(Node, CId, Me)),
    node_clear_current,
    (   var(E)
    ->  true
    ;   connection_ended(Node, Peer, E)
    ).

node_set_current_if_alive(Node) :-
    (   local_node(Node)
    ->  node_set_current(Node)
    ;   throw(node_stopping)
    ).

%   Called after the clean-up. An abort (the host stopping every thread,
%   as pybridge's close does) goes on up, so that the pool worker exits
%   instead of waiting for the next connection.
connection_ended(_, _, node_stopping) :- !.
connection_ended(_, _, dfrl_evicted) :- !.
connection_ended(_, _, '$aborted') :- !, throw('$aborted').
connection_ended(_, _, unwind(A)) :- !, throw(unwind(A)).
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

%!  connection_evict(+Node, +ConnId) is det.
%
%   Tell the worker serving ConnId of Node, if one does, to close it.
%   Its admission entry is gone already (node_admission.pl); a worker
%   that has not recorded itself yet finds that when it starts (see
%   serve_connection/4: it records itself, then looks).

connection_evict(Node, Victim) :-
    debug(dfrl(node), '~w: evicting unauthenticated connection ~w', [Node, Victim]),
    (   connection(Node, Victim, T)
    ->  pool_signal(connections, T, evict_if_serving(Node, Victim))
    ;   true
    ).

evict_if_serving(Node, CId) :-
    (   serving(Node, CId)
    ->  throw(dfrl_evicted)
    ;   true
    ).

%!  connection_stop_all(+Node) is det.
%
%   Tell every worker serving a connection of Node to close it (Node is
%   stopping).

connection_stop_all(Node) :-
    forall(connection(Node, _, T),
           pool_signal(connections, T, stop_if_serving(Node))).

%   Signalled to a pooled worker when Node stops; harmless if the worker
%   has moved on to another job.
stop_if_serving(Node) :-
    thread_self(Me),
    (   connection(Node, _, Me)
    ->  throw(node_stopping)
    ;   true
    ).

%!  connection_forget_node(+Node) is det.
%
%   Node has stopped: forget the connections recorded for it.

connection_forget_node(Node) :-
    retractall(connection(Node, _, _)).

		 /*******************************
		 *        HELLO AND FRAMES	*
		 *******************************/

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
    set_stream(Out, record_position(false)),    % frames move in bulk (wire.pl)
    node_option(Node, idle_timeout, Idle),
    set_stream(In, timeout(Idle)),
    node_id_new(Nonce),
    node_property(Node, id(Id)),
    node_property(Node, address(Host:Port)),
    node_option(Node, auth_idle_timeout, AuthIdle),
    wire_version(V),
    frame_write(Out, text,
                hello(V, Nonce, node(Host, Port, [id(Id), idle(Idle),
                                                  auth_idle(AuthIdle)]))),
    ctx_new(Node, Peer, Nonce, In, Out, PeerName, Ctx),
    serve_frames(Ctx).

%   The idle limit is set before every frame: a request's After goal may
%   have changed the stream's timeout (a staged migration waits for its
%   commit with the commit timeout). Once the peer is authenticated, the
%   input records no position, so that a binary frame's body is moved in
%   bulk (wire.pl); before, it does: the deadline reader's
%   read_pending_codes/3 fails on a TLS stream without one (SWI-Prolog
%   9.0.4: "I/O error in read ... Invalid argument"). Once the peer
%   proved a token, the input buffer grows to 64 KiB (serve_term/3 of
%   auth(Proofs), while the peer waits for the answer: what the buffer
%   holds is kept): a large frame is then read in a sixteenth of the
%   read(2) calls. An unauthenticated connection keeps the default 4 KiB.
serve_frames(Ctx) :-
    ctx_node(Ctx, Node),
    ctx_input(Ctx, In),
    ctx_output(Ctx, Out),
    (   ctx_authenticated(Ctx)
    ->  set_stream(In, record_position(false)),  % see below
        node_option(Node, max_frame_size, Max),
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
    await_frame(In, Idle),
    hop_probe(frame_arrived),
    set_stream(In, timeout(Idle)),
    catch(frame_read(In, Frame, [body_size(Size)|ReadOptions]),
          error(wire_error(Reason), _),
          ( request_reply(Out, error(error(wire_error(Reason), _))),
            Frame = end_of_file,
            rejected_frame(Reason)
          )),
    hop_probe(frame_read(Frame)),
    (   Frame == end_of_file
    ->  true
    ;   Frame = frame(_, Term),
        serve_term(Term, Ctx, Continue),
        (   Size > 4194304
        ->  release_memory
        ;   true
        ),
        (   Continue == true
        ->  serve_frames(Ctx)
        ;   true
        )
    ).

%   Wait at most Idle seconds for the first byte of the next frame (or
%   the end of the stream), in slices of a second: between two slices
%   the worker runs Prolog again, so that a signal (the node stopping,
%   an eviction, the host aborting its threads) is taken even by a
%   process that embeds Prolog without OS signal handling, where a
%   blocked read is never interrupted.
await_frame(In, Idle) :-
    get_time(Now),
    Deadline is Now + Idle,
    await_frame_(In, Deadline, Idle).

await_frame_(In, Deadline, Idle) :-
    get_time(Now),
    Left is Deadline - Now,
    (   Left =< 0
    ->  throw(error(timeout_error(read, In), context(_, idle(Idle))))
    ;   Slice is min(1.0, Left),
        set_stream(In, timeout(Slice)),
        catch(peek_byte(In, _), error(timeout_error(_, _), _), Timeout = true),
        (   Timeout == true
        ->  await_frame_(In, Deadline, Idle)
        ;   true
        )
    ).

serve_term(auth(Proofs), Ctx, true) :-
    !,
    ctx_node(Ctx, Node),
    ctx_nonce(Ctx, Nonce),
    ctx_output(Ctx, Out),
    (   is_list(Proofs),
        node_accepts(Node, Proofs/Nonce)
    ->  ctx_set_authenticated(Ctx, true),
        mark_authenticated(Node),
        ctx_input(Ctx, In),
        set_stream(In, buffer_size(65536)),     % see below
        request_reply(Out, ok(authenticated))
    ;   ctx_set_authenticated(Ctx, false),
        node_property(Node, address(Here)),
        request_reply(Out, error(error(permission_error(authenticate, platform, Here), _)))
    ).
serve_term(Request, Ctx, Continue) :-
    ctx_node(Ctx, Node),
    ctx_peer(Ctx, Peer),
    ctx_output(Ctx, Out),
    debug(dfrl(request), '~w: ~p from ~p', [Node, Request, Peer]),
    catch(request_handle(Request, Ctx, Reply, After), E,
          ( Reply = error(E), After = true )),
    (   Reply == none
    ->  true
    ;   request_reply(Out, Reply),
        hop_probe(replied(Request))
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

%   The connection's class becomes authenticated (it no longer counts
%   against the unauthenticated caps).
mark_authenticated(Node) :-
    (   serving(Node, CId)
    ->  admission_authenticated(Node, CId)
    ;   true
    ).

		 /*******************************
		 *      MEMORY AND PARSERS	*
		 *******************************/

%   After a rejected frame: give its memory back. A reader that ran out of
%   C stack leaves the pages it touched resident in this thread (no trim
%   returns them), so its worker exits when the connection ends.
rejected_frame(Reason) :-
    (   Reason = syntax(resource_error(_))
    ->  pool_retire
    ;   true
    ),
    release_memory.

%   Give back what a large or rejected frame made the worker's stacks grow
%   to (a worker thread is reused, and a hostile frame must not leave its
%   memory behind): collect, shrink the stacks, and hand freed memory back
%   to the OS (trim_heap/0; tcmalloc otherwise keeps it).
release_memory :-
    garbage_collect,
    trim_stacks,
    catch(trim_heap, _, true).

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
