:- module(node_acceptor,
          [ acceptor_run/2,             % +Node, +Socket
            acceptor_stopping/1,        % +Node
            acceptor_stopped/1          % +Node
          ]).
:- use_module(wire, [frame_write/3]).
:- use_module(worker_pool, [pool_run/3]).
:- use_module(node_registry, [registry_bound/3, node_option/3]).
:- use_module(node_admission, [admission_admit/5, admission_forget/2]).
:- use_module(node_connection, [connection_serve/4, connection_evict/2]).
:- autoload(library(socket), [tcp_accept/3, tcp_close_socket/1, tcp_open_socket/2]).
:- autoload(library(aggregate), [aggregate_all/3]).

/** <module> A node's acceptor: connections handed to workers

The acceptor thread of a node (node.pl starts it with acceptor_run/2)
takes each connection, asks admission (node_admission.pl) whether it may
stay, and hands it to a connection worker (node_connection.pl) of the
process's pool; a connection that may not stay is told so and closed.
*/

:- dynamic
    stopping/1.                 % Node

%!  acceptor_stopping(+Node) is det.
%!  acceptor_stopped(+Node) is det.
%
%   Node is stopping: its acceptor closes what it accepts and ends. Node
%   stopped: forget that.

acceptor_stopping(Node) :-
    assertz(stopping(Node)).

acceptor_stopped(Node) :-
    retractall(stopping(Node)).

%!  acceptor_run(+Node, +Socket) is det.
%
%   Accept connections on Socket, Node's listening socket, until Node
%   stops. Run in the node's acceptor thread.

acceptor_run(Node, Socket) :-
    accept_loop(Node, Socket).

accept_loop(Node, Socket) :-
    catch(tcp_accept(Socket, Client, Peer), E, true),
    (   stopping(Node)
    ->  (   var(E) -> tcp_close_socket(Client) ; true )
    ;   nonvar(E)
    ->  print_message(warning, E),
        (   registry_bound(Node, _, _) -> accept_loop(Node, Socket) ; true )
    ;   dispatch(Node, Client, Peer),
        accept_loop(Node, Socket)
    ).

%   Admission (node_admission.pl) keeps slots for authenticated peers:
%   an unauthenticated newcomer at a cap evicts the oldest
%   unauthenticated connection of the peer holding the most; only when
%   every slot is authenticated is a connection refused.
dispatch(Node, Client, Peer) :-
    peer_key(Peer, Key),
    flag(dfrl_conn_ids, CId, CId+1),
    node_option(Node, max_connections, Max),
    node_option(Node, max_unauth_connections, MaxU),
    node_option(Node, max_unauth_per_peer, MaxP),
    admission_admit(Node, CId, Key, limits(Max, MaxU, MaxP), Verdict),
    (   Verdict = refuse
    ->  refuse_busy(Node, Client)
    ;   Verdict = evict(Victim)
    ->  connection_evict(Node, Victim)
    ;   true
    ),
    (   Verdict == refuse
    ->  true
    ;   connection_workers_max(MaxWorkers),
        catch(pool_run(connections, connection_serve(Node, CId, Client, Peer),
                       [max(MaxWorkers)]),
              E, ( print_message(warning, E),
                   admission_forget(Node, CId),
                   refuse_busy(Node, Client) ))
    ->  true
    ;   true
    ).

%   The connection pool (shared by the nodes of the process) holds twice
%   their connections: room for evicted workers that are still ending,
%   but not for a flood to grow it without bound.
connection_workers_max(Max) :-
    aggregate_all(sum(M), ( registry_bound(N, _, _), node_option(N, max_connections, M) ),
                  Sum),
    Max is max(16, 2 * Sum).

peer_key(ip(A,B,C,D), ip(A,B,C,D)) :- !.
peer_key(Peer, Peer).

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
