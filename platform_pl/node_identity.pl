:- module(node_identity,
          [ node_for_address/2,         % +Address, -Node
            node_listens_at/2,          % +Node, +Address
            node_is_self/2,             % +Node, +Address
            wildcard_host/1,            % +Host
            advertised_address/4        % +Options, +Host, +Bound, -Advertised
          ]).
:- use_module(transport, [address_normalize/2, transport_identify/3]).
:- use_module(node_registry,
              [registry_bound/3, registry_ident/4, current_node/1, node_option/3]).
:- autoload(library(socket), [tcp_socket/1, tcp_bind/2, tcp_close_socket/1, gethostname/1]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(lists), [max_list/2]).

/** <module> "Is this address me?": a node's identity, not its address text

An address reaches a node of this process if it is literally one the
node binds or advertises, or if the node that answers there has its id
(the hello of a connection). node.pl re-exports these predicates.
*/

:- dynamic
    local_host_seen/3.          % Host, Local (true/false), Time: host_is_local/1

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
    (   registry_bound(N, _, _),
        literal_self(N, Address)
    ->  Node = N
    ;   findall(T, registry_ident(_, _, _, T), Starts),
        Starts \== [],
        max_list(Starts, Since),
        identify(Address, Since, Id),
        registry_ident(N, Id, _, _)
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
%   host name. An address that cannot be reached is not Node, and one
%   that is not this host's is not asked (no socket binds to it).

node_is_self(Node, Address0) :-
    address_normalize(Address0, Address),
    registry_ident(Node, Id, _, Started),
    (   literal_self(Node, Address)
    ->  true
    ;   identify(Address, Started, Id)
    ).

identify(Address, Since, Id) :-
    host_is_local(Address),
    (   catch(current_node(Here), _, fail)
    ->  node_option(Here, connect_timeout, CT)
    ;   CT = 5
    ),
    catch(transport_identify(Address, Id0,
                             [since(Since), connect_timeout(CT),
                              reply_timeout(CT)]),
          E, ( debug(dfrl(node), 'identify ~w: ~p', [Address, E]), fail )),
    Id = Id0.

%   Only an address of this host can reach a node of this process: the
%   kernel says so when a socket binds to it (EADDRNOTAVAIL otherwise),
%   without a packet sent. A remote address is thus never connected to
%   for its id, so asking "is this me?" of a stop that is cut off or
%   down costs microseconds, not a connect timeout (a mover asks it
%   once a hop). The kernel's answer (a socket, a bind, a close: about
%   30 us) is kept for 10 s per host name, so a hop pays a lookup.
host_is_local(Host:_) :-
    get_time(Now),
    (   local_host_seen(Host, Local, T),
        Now - T < 10
    ->  true
    ;   (   setup_call_cleanup(
                tcp_socket(Socket),
                catch(tcp_bind(Socket, Host:0), _, fail),
                tcp_close_socket(Socket))
        ->  Local = true
        ;   Local = false
        ),
        with_mutex(dfrl_node_local_hosts,
                   ( retractall(local_host_seen(Host, _, _)),
                     assertz(local_host_seen(Host, Local, Now)) ))
    ),
    Local == true.

literal_self(Node, Host:Port) :-
    (   registry_ident(Node, _, AH:AP, _),
        AP =:= Port,
        same_host(Host, AH)
    ->  true
    ;   registry_bound(Node, BH:BP, _),
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


%!  wildcard_host(+Host) is semidet.
%
%   Host binds every interface.

wildcard_host(H) :-
    atomic(H),
    atom_string(A, H),
    memberchk(A, ['0.0.0.0', '::', '']).

%!  advertised_address(+Options, +Host, +Bound, -Advertised) is det.
%
%   The address a node bound to Host:Bound advertises: its option
%   advertise(A) (a host, or Host:Port with 0 for the bound port), else
%   the host name for a wildcard host, else Host:Bound.

advertised_address(Options, Host, Bound, Advertised) :-
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
