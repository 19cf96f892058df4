:- module(code_safety,
          [ check_agent_record/1,       % +Record
            check_program_text/2,       % +Id, +Text
            check_post/3,               % +Node, +Agent, +Goal
            code_trusted/1,             % +Ctx
            forget_checked_code/0,
            peer_trusted/2,             % +Node, +PeerName
            record_seal/3,              % +MigId, +Record, -Seal
            record_sealed/3             % +MigId, +Record, +Seal
          ]).
:- dynamic apply_macros_was_loaded/0.
:- (   current_module(apply_macros)
   ->  assertz(apply_macros_was_loaded)
   ;   true
   ).
:- use_module(library(sandbox), []).
:- use_module(sandbox_policy, [policy_safe_goal/1, safe_library/1]).
%   library(sandbox) loads library(apply_macros), whose goal expansion of
%   maplist/N then applies to all code compiled later in the process and
%   changes what it means (a yall lambda's free variables are copied
%   instead of shared). The sandbox needs none of it: unless the process
%   loaded apply_macros itself, its expansion clauses are taken out again.
:- (   apply_macros_was_loaded
   ->  true
   ;   forall(( member(H, [goal_expansion(_, _), goal_expansion(_, _, _, _)]),
                clause(system:H, Body, Ref),
                Body = apply_macros:_ ),
              erase(Ref))
   ).
:- use_module(node, [ctx_node/2, node_property/2]).
:- use_module(agents, [agent_property/3]).
:- autoload(library(error), [must_be/2, permission_error/3]).
:- autoload(library(lists), [member/2, append/2, append/3]).
:- autoload(library(apply), [maplist/2, include/3, exclude/3]).
:- autoload(library(crypto), [crypto_n_random_bytes/2, crypto_data_hash/3]).

/** <module> Mobile code: what arrives over the network runs in a sandbox

Code that a peer sends (an arriving agent's clauses, a program sent
with load_program_at/3 or load_program_text/4) is checked here before
anything of it is installed, with SWI-Prolog's library(sandbox) extended
with the platform's agent API. Locally consulted programs, agents made
on this node and agents sent by a node of this process are trusted.

Rules (a refusal is error(permission_error(install, code, Culprit), _),
Culprit the offending goal, clause head or directive):

  - Every clause body may call only what library(sandbox) deems safe
    (pure computation, lists, arithmetic, strings, format/2 to an atom
    or to current output, assert/retract of *facts* in the agent's own
    module), output to the agent's output (nl/0, print/1, write/1,
    flush_output/0, format/3 to user_output/user_error) and the agent
    API (agent_api/2). Shell, files, halt, foreign calls, op/3, flags,
    qualified asserts (another module), asserted rules and any other
    predicate of a platform module (node, transport, tokens, handlers
    of platform_request) are refused.
  - API calls that name an agent (move, clone, payload, purge) must name
    the agent itself: `guid` in a program, the agent's own name (or the
    first argument of its handler) in an agent's clauses.
  - A goal whose predicate cannot be told (call/1 of a variable) or an
    undefined predicate is refused.
  - An agent's handler must be defined by its own clauses.
  - A program loads into a module of its own (codeload.pl,
    program_module/2) and may define clauses of its own predicates
    there (unqualified heads) and of the hooks declared with
    mobile_hook/1 (the dFRL aggregation hooks), nothing else. Hooks are
    default-deny: no clause or declaration, qualified or not, of a name
    that the Prolog system, a library or the node calls by name
    (hook_refusal/3: SWI-Prolog's hooks called by name, names of
    `system`, of `prolog` and of the node's `user`, names declared
    multifile anywhere, library exports); the refusal's culprit is
    hook(Module:Name/Arity). Its directives may only declare its
    predicates (dynamic, discontiguous, non_terminal), load libraries,
    and name safe initialization goals, which codeload.pl runs after
    the load under the agent bounds.

Side doors. library(sandbox) judges a goal by the predicates it calls;
some goals run without being a visible call in the checked code. Each
family, and what is done about it (sandbox_policy.pl holds the table of
refusals, applied at any depth of the sandbox's walk):

  | family                                | here                        |
  |---------------------------------------|-----------------------------|
  | attribute hooks: put_attr/3, put_attrs/2 (attr_unify_hook, attribute_goals, portray_attvar of the attribute's module run with the value), freeze/when/dif | refused: put_attr(V, freeze, user:shell(C)), V = 1 ran C |
  | attributed variables or cycles in data (records, binary frames) | refused before anyone unifies them (wire.pl for frames, plain_data/1 for programs) |
  | directives of programs                | only declarations of the program's own predicates, libraries of an allow-list (sandbox_policy:safe_library/1), initialization/1 and initialization(G, now) with G checked and run after the load under the agent bounds and a wall clock (codeload.pl; a loop used to spin a connection worker for ever); if/elif, op, flags, include, module, table, encoding refused |
  | quasi quotations                      | refused: their parsers run when the text is read |
  | print_message/2, message_to_string/2, message translation | refused: a format(F, A) message with ~@ calls a goal, and message hooks are the node's |
  | format/1,2,3                          | ~@ arguments checked by the sandbox; ~W refused (its options may hold portray_goal(G)); output only to atoms/strings, current output, user_output, user_error |
  | portray, print                        | print/1 and ~p call the node's portray/1 hook, which a peer cannot define (hooks are refused by name) |
  | hooks the system calls by name, declared or not (prolog_exception_hook/4 is not declared in 9.0.4: with `repeat, fail` it spun a worker at every malformed frame of an unauthenticated peer), exception/3, thread_message_hook/3, prolog_trace_interception/4, prolog_event_hook/1, portray_attvar/1, prolog_predicate_name/2, prolog:message//1, ... | refused by name, in the program's module or qualified (hook_refusal/3); on_signal/3 and at_halt/1 are not in the sandbox |
  | goal and term expansion               | a program may not define expansion hooks (they would run in its module while it loads, after the check); the node's own expand the checked terms |
  | names in `user`                       | programs sent by peers load into modules of their own: the first program to define a name no longer owns it for every other peer's program |
  | flags: set_prolog_flag/2, create_prolog_flag/3, set_prolog_stack/2 | refused: flags are the process's (double_quotes broke every later program load) |
  | reading flags                         | only arithmetic and syntax flags (argv, os_argv, executable, home are refused: argv held tokens) |
  | environment: getenv/2, setenv/2       | refused (the sandbox has neither) |
  | global variables (b_/nb_getval, b_/nb_setval, nb_current) | refused: agents run in the platform's pooled threads |
  | flag/3, recorded database, char_conversion/2, op/3, style_check/1 | refused: tables of the whole process |
  | tabling                               | refused: tables outlive the call |
  | loading code at run time (use_module, load_files, consult) | refused |
  | setup_call_cleanup/3, call_cleanup/2,3, setup_call_catcher_cleanup/4 | refused: a cleanup runs after the platform stopped the agent |
  | catch/3 with a catcher that could be the platform's stop ('$aborted', '$dfrl_purged', '$dfrl_bound'(_), time_limit_exceeded, a variable) | refused, and throwing one of them too: an agent over a bound must stop |
  | abort/0                               | refused: it unwinds the platform's worker |
  | clause/2 of a variable                | refused                     |
  | other agents                          | agent_property/3 of another agent gives only handler, kind, status, hops; modules of other agents cannot be called (not exported) |
  | error terms (thrown by an agent, sent by a peer in a reply) | printed only if inert (platform_errors:inert_error/2); a `~` in any text makes them foreign_error(Text) |

A node trusts peers by name with the node option trusted_peers(Names):
code from a peer whose TLS certificate names one of them is installed
unchecked (node:ctx_peer_name/2; a plaintext peer is never trusted by
name).
*/

:- multifile
    mobile_hook/1,              % ?Module:Name/Arity
    agent_api/2.                % +Module:Goal, -Condition

:- dynamic process_key/1.
:- dynamic checked_code/1.              % Sha: code accepted since the last load

%!  mobile_hook(?PI) is nondet.
%
%   Multifile: Module:Name/Arity is a hook that programs sent by peers
%   may add clauses to (their bodies are checked as any other). E.g.
%
%   ```
%   code_safety:mobile_hook(my_module:my_hook/2).
%   ```

mobile_hook(dfrl_aggregation:aggregate_init/3).
mobile_hook(dfrl_aggregation:aggregate_step/4).
mobile_hook(dfrl_aggregation:aggregate_final/3).
mobile_hook(dfrl_aggregation:method_uses_visits/1).
mobile_hook(dfrl_aggregation:method_applies/2).

		 /*******************************
		 *            TRUST		*
		 *******************************/

%!  code_trusted(+Ctx) is semidet.
%
%   True if the peer of connection Ctx is trusted by name: the node has
%   the option trusted_peers(Names) and the peer's TLS certificate names
%   one of them.

code_trusted(Ctx) :-
    ctx_node(Ctx, Node),
    catch(node:ctx_peer_name(Ctx, Name), error(existence_error(_, _), _), fail),
    peer_trusted(Node, Name).

%!  peer_trusted(+Node, +PeerName) is semidet.
%
%   True if Node's option trusted_peers(Names) names PeerName.

peer_trusted(Node, Name) :-
    node_property(Node, option(trusted_peers(Names))),
    is_list(Names),
    atom_string(Name, S),
    member(N, Names),
    atom_string(N, S),
    !.

%   A record sent by a node of this process is sealed with a key that
%   never leaves the process: its code was trusted (or checked) here.
key(Key) :-
    (   process_key(Key)
    ->  true
    ;   with_mutex(code_safety_key,
                   (   process_key(Key)
                   ->  true
                   ;   crypto_n_random_bytes(32, Bytes),
                       atom_codes(Key, Bytes),
                       assertz(process_key(Key))
                   ))
    ).

%!  record_seal(+MigId, +Record, -Seal) is det.
%
%   Seal is an HMAC, with this process's key, of migration MigId and
%   Record (as sent): record_sealed/3 accepts it in this process only.

record_seal(MigId, Record, Seal) :-
    key(Key),
    variant_sha1(MigId-Record, Sha),
    crypto_data_hash(Sha, Seal, [algorithm(sha256), hmac(Key)]).

%!  record_sealed(+MigId, +Record, +Seal) is semidet.

record_sealed(MigId, Record, Seal) :-
    atom(Seal),
    catch(record_seal(MigId, Record, Seal0), _, fail),
    Seal0 == Seal.

		 /*******************************
		 *        AGENT RECORDS		*
		 *******************************/

%!  check_agent_record(+Record) is det.
%
%   Check the code of an agent record that arrived from a peer (see the
%   module comment).
%
%   @error permission_error(install, code, Culprit)

check_agent_record(Record) :-
    (   Record = agent(Name0, Handler, _, _, _, Preds, Clauses, _),
        is_list(Preds), is_list(Clauses)
    ->  true
    ;   throw(error(type_error(agent_record, Record), _))
    ),
    (   Name0 = rename(Self, _) -> true ; Self = Name0 ),
    maplist(clause_parts, Clauses, Parts),
    maplist(check_head, Parts),
    (   member(H-_, Parts), callable(H), functor(H, Handler, A), A >= 3
    ->  true
    ;   refuse(handler(Handler), 'the handler is not defined by the agent''s own clauses')
    ),
    include(is_rule, Parts, Rules),
    variant_sha1(Self-Handler-Preds-Rules, Key),
    (   Rules == []
    ->  true
    ;   checked_code(Key)
    ->  true
    ;   with_scratch(Preds, Rules,
                     [S]>>forall(member(R, Rules),
                                 check_rule(S, Self, Handler, R))),
        remember_checked(Key)
    ).

%   The code of a record (its rules: the facts are data and are not
%   walked, nor is a payload of 100,000 floats) is checked once; its
%   hash is kept until a program is loaded (which may define what a
%   refused agent lacked, or redefine nothing: programs may not redefine
%   the node's predicates) and at most 512 of them.
remember_checked(Key) :-
    with_mutex(code_safety_cache,
               (   predicate_property(checked_code(_), number_of_clauses(N)),
                   N >= 512
               ->  retractall(checked_code(_)),
                   assertz(checked_code(Key))
               ;   assertz(checked_code(Key))
               )).

%!  forget_checked_code is det.
%
%   Forget which agent code was accepted: called after code is loaded
%   into the node (codeload.pl), which changes what the sandbox sees.

forget_checked_code :-
    retractall(checked_code(_)).

%   Records reach the check from frames only: a text frame cannot hold
%   attributed variables or cycles and wire.pl refuses a binary frame
%   with them, so the data is not walked again here.
%   Data with no attributed variables and no cycles: nothing runs when
%   it is unified, copied or asserted.
plain_data(T) :-
    (   acyclic_term(T), term_attvars(T, [])
    ->  true
    ;   refuse(data, 'cyclic terms or attributed variables')
    ).

clause_parts((H:-B), H-B) :- !.
clause_parts(H, H-true).

is_rule(_-B) :- B \== true.

check_head(H-_) :-
    (   var(H)
    ->  refuse(clause_head(H), 'a variable as clause head')
    ;   \+ callable(H)
    ->  refuse(clause_head(H), 'not callable')
    ;   H = _:_
    ->  refuse(clause_head(H), 'a clause for another module')
    ;   functor(H, F, A), control(F/A)
    ->  refuse(clause_head(H), 'a control construct as clause head')
    ;   true
    ).

control((:-)/2). control((:-)/1). control((?-)/1). control((-->)/2).
control((',')/2). control((;)/2). control((->)/2). control((*->)/2).
control((\+)/1). control((@)/2).

%   A handler clause is called by the platform with the agent's own name
%   first (agent_execute/4, a post): its first argument is the agent.
check_rule(S, Self, Handler, H0-B0) :-
    copy_term(H0-B0, H-B),
    (   functor(H, Handler, A), A >= 3, arg(1, H, Me), var(Me)
    ->  Me = Self
    ;   true
    ),
    check_body(S, Self, B).

		 /*******************************
		 *      THE SANDBOX CHECK	*
		 *******************************/

%   check_body(+Module, +Self, +Body): conjunct by conjunct, left to
%   right, applying the unifications of the top-level conjunction to the
%   goals after them (so that Mod = m, call(Mod:G) is understood).
check_body(S, Self, (A, B)) :-
    !,
    check_body(S, Self, A),
    check_body(S, Self, B).
check_body(_, _, X = Y) :-
    !,
    ( X = Y -> true ; true ).
check_body(S, Self, G) :-
    copy_term(G, G1),
    b_setval(code_safety_self, Self),
    catch(policy_safe_goal(S:G1), E, sandbox_refusal(S, G, E)),
    b_setval(code_safety_self, '$none').

sandbox_refusal(_, _, error(permission_error(install, code, C), Ctx)) :-
    !,
    throw(error(permission_error(install, code, C), Ctx)).
sandbox_refusal(S, _, error(permission_error(call, sandboxed, G), Ctx)) :-
    !,
    unscratch(S, G, C),
    (   nonvar(Ctx), Ctx = sandbox(_, [policy(Why)|_])
    ->  refuse(C, Why)
    ;   refuse(C, 'not allowed in the sandbox')
    ).
sandbox_refusal(S, G0, error(existence_error(procedure, PI), _)) :-
    !,
    unscratch(S, PI, C),
    unscratch(S, G0, G),
    refuse(undefined(C, G), 'calls a predicate this node does not define').
sandbox_refusal(S, G0, error(instantiation_error, _)) :-
    !,
    unscratch(S, G0, G),
    refuse(unknown_call(G), 'cannot tell which predicate it calls').
sandbox_refusal(S, G0, error(Formal, _)) :-
    unscratch(S, G0, G),
    refuse(G, Formal).

unscratch(S, T0, T) :-
    (   T0 = M:T1, M == S
    ->  T = T1
    ;   T = T0
    ).

refuse(Culprit, Why) :-
    throw(error(permission_error(install, code, Culprit),
                context(code_safety, Why))).

%   with_scratch(+Preds, +Rules, :Goal): the code under check, in a
%   module that inherits from `user` as agents' modules do, so that the
%   sandbox sees the calls between its predicates.
:- meta_predicate with_scratch(+, +, 1).

with_scratch(Preds, Rules, Goal) :-
    with_mutex(code_safety_scratch,
               setup_call_cleanup(
                   scratch_fill(Preds, Rules, S),
                   call(Goal, S),
                   scratch_clear(S))).

scratch_module(code_safety_scratch).

scratch_fill(Preds, Rules, S) :-
    scratch_module(S),
    scratch_clear(S),
    dynamic(S:'$scratch'/0),            % the module exists, even for no rules
    catch(( forall(( member(P, Preds), P = F/A, atom(F), integer(A) ),
                   dynamic(S:F/A)),
            forall(member(H-B, Rules),
                   ( functor(H, F, A), dynamic(S:F/A), assertz(S:(H:-B)) ))
          ),
          error(E, _),
          refuse(clause(E), 'cannot define it')).

scratch_clear(S) :-
    forall(( current_predicate(S:F/A),
             functor(H, F, A),
             predicate_property(S:H, dynamic),
             \+ predicate_property(S:H, imported_from(_)) ),
           abolish(S:F/A)).

		 /*******************************
		 *            POSTS		*
		 *******************************/

%!  check_post(+Node, +Agent, +Goal) is det.
%
%   Goal, Handler(Agent, Link, Args...), is an event that Agent on Node
%   declares: one of the list of its fact '$agent_events'(List) (the
%   agent_create/4 option events(List)), or without it, an arity of its
%   handler that the agent's own module defines (Tartarus programs post
%   to their handler's clauses).
%
%   @error permission_error(post, event, Handler/Arity)

check_post(Node, Agent, Goal) :-
    functor(Goal, Handler, Arity),
    agent_property(Node, Agent, module(M)),
    (   catch(M:'$agent_events'(Events), _, fail)
    ->  memberchk(Handler/Arity, Events)
    ;   Arity >= 3,
        functor(H, Handler, Arity),
        current_predicate(M:Handler/Arity),
        \+ predicate_property(M:H, imported_from(_))
    ),
    !.
check_post(_, _, Goal) :-
    functor(Goal, Handler, Arity),
    throw(error(permission_error(post, event, Handler/Arity),
                context(check_post/3, 'not an event this agent declares'))).

		 /*******************************
		 *           PROGRAMS		*
		 *******************************/

%!  check_program_text(+Id, +Text) is det.
%
%   Check a program a peer sent (see the module comment) before it is
%   loaded as dfrl_program://Id into a module of its own (codeload.pl,
%   program_module/2): its clauses define its own predicates (none the
%   Prolog system, a library or the node calls by name: hook_refusal/3)
%   and the mobile hooks (mobile_hook/1); its directives declare them,
%   load safe libraries and name initialization goals, which are
%   checked here as bodies and run later under the agent bounds.
%
%   @error permission_error(install, code, Culprit)
%   @error syntax_error(...) if Text does not read.

check_program_text(Id, Text) :-
    must_be(atomic, Id),
    must_be(string, Text),
    setup_call_cleanup(open_string(Text, In),
                       read_program(In, Terms0),
                       close(In)),
    plain_data(Terms0),
    findall(Head, ( member(T, Terms0), raw_head(T, Head) ), Heads0),
    sort(Heads0, Heads),                        % each name is looked up once
    maplist(head_hook_check, Heads),
    maplist(expand, Terms0, Expanded),
    append(Expanded, Terms),
    partition_terms(Terms, Directives, Clauses),
    maplist(check_directive, Directives),
    maplist(program_clause, Clauses, Parts),
    findall(PI, ( member(own-H-_, Parts), functor(H, F, A), PI = F/A ), Own0),
    sort(Own0, Own),
    maplist(own_predicate, Own),
    findall(P, ( member(D, Directives), declared(D, P) ), Declared),
    include(own_part, Parts, OwnParts),
    findall(H-B, ( member(own-H-B, OwnParts), B \== true ), LocalRules),
    findall(F/A, ( member(own-H-_, OwnParts), functor(H, F, A) ), Local0),
    append(Declared, Local0, Local),
    findall(B, ( member(_-_-B, Parts), B \== true ), Bodies),
    findall(G, ( member(D, Directives), directive_init(D, G) ), Inits),
    append(Bodies, Inits, ToCheck),
    (   ToCheck == []
    ->  true
    ;   with_scratch(Local, LocalRules,
                     [S]>>forall(member(B, ToCheck), check_body(S, guid, B)))
    ).

%   Quasi quotations are parsed by hooks when the text is read (the
%   checker's read and the loader's): a program may not use them.
read_program(In, Terms) :-
    read_term(In, T, [module(user), syntax_errors(error), quasi_quotations(QQ)]),
    (   QQ \== []
    ->  refuse(quasi_quotation(T), 'quasi quotations run parsers when read')
    ;   T == end_of_file
    ->  Terms = []
    ;   Terms = [T|Rest],
        read_program(In, Rest)
    ).

%   A grammar rule's translation declares its head non_terminal/1 (in
%   the module it is read in): the declaration is the rule's, not a
%   directive of the program.
expand(T, Ts) :-
    expand_term(T, X),
    (   is_list(X) -> Ts0 = X ; Ts0 = [X] ),
    (   nonvar(T), T = (_ --> _)
    ->  exclude(non_terminal_decl, Ts0, Ts)
    ;   Ts = Ts0
    ).

non_terminal_decl((:- non_terminal(_))).

%   Clause heads are checked for hooks before the terms are expanded:
%   expansion runs the node's hooks on them (library(sandbox)'s refuses
%   a sandbox:safe_primitive/1 clause without naming the hook).
raw_head(T, M-(F/A)) :-
    nonvar(T),
    T \= (:- _),
    T \= (?- _),
    (   T = Q:(QH :- _),                        % Module:(Head :- Body)
        atom(Q), callable(QH)
    ->  strip_module(Q:QH, M, H),
        callable(H),
        functor(H, F, A)
    ;   T = (H0 --> _)
    ->  (   nonvar(H0), H0 = (H1, _) -> true ; H1 = H0 ),
        callable(H1),
        strip_module('$program':H1, M, H),
        callable(H),
        functor(H, F, A0),
        A is A0 + 2
    ;   clause_parts(T, QH-_),
        callable(QH),
        strip_module('$program':QH, M, H),
        callable(H),
        functor(H, F, A)
    ).

head_hook_check(M-(F/A)) :-
    (   M \== '$program',
        (   mobile_hook(M:F/A)
        ;   moved_hook(M:F/A, _)
        )
    ->  true                                    % program_clause/2 tells
    ;   M == '$program'
    ->  own_predicate(F/A)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  refuse(hook(Q:F/A), Why)
    ;   true
    ).

partition_terms([], [], []).
partition_terms([(:- D)|Ts], [D|Ds], Cs) :- !, partition_terms(Ts, Ds, Cs).
partition_terms([(?- D)|Ts], [D|Ds], Cs) :- !, partition_terms(Ts, Ds, Cs).
partition_terms([C|Ts], Ds, [C|Cs]) :- partition_terms(Ts, Ds, Cs).

own_part(own-_-_).

%   program_clause(+Clause, -Where-Head-Body): Where is `own` for a
%   clause of the program's own module (an unqualified head), else the
%   module of a mobile hook.
program_clause(Clause, Where-H-B) :-
    clause_parts(Clause, QH-B),
    (   var(QH) -> refuse(clause_head(QH), 'a variable as clause head') ; true ),
    strip_module('$program':QH, M, H),
    check_head(H-B),
    functor(H, F, A),
    (   M == '$program'
    ->  Where = own
    ;   mobile_hook(M:F/A)
    ->  Where = M
    ;   moved_hook(M:F/A, To)
    ->  refuse_moved(M:F/A, To)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  refuse(hook(Q:F/A), Why)
    ;   refuse(clause_head(M:H), 'a clause for another module')
    ).

%   qualified_hook(+Module, +PI, -Q, -Why): a clause or declaration for
%   Module:PI would define a hook: Module is user, prolog or system, or
%   declares PI multifile, or the system calls PI by name.
qualified_hook(M, F/A, Q, Why) :-
    hook_refusal(F/A, Q, Why),
    (   memberchk(M, [user, prolog, system])
    ->  true
    ;   called_by_name(_:F/A)
    ->  true
    ;   atom(M),
        current_module(M),                      % makes no module, loads nothing
        current_predicate(M:F/A),
        functor(H, F, A),
        predicate_property(M:H, multifile)
    ),
    !.

%   A program's own predicate: one that nothing calls by name.
own_predicate(PI) :-
    (   hook_refusal(PI, Q, Why)
    ->  refuse(hook(Q:PI), Why)
    ;   true
    ).

%   Directives: declarations of the program's own predicates, libraries
%   and initialization goals (checked as bodies).
check_directive(D) :-
    (   var(D)
    ->  refuse(directive(D), 'a variable')
    ;   D = (A, B)
    ->  check_directive(A),
        check_directive(B)
    ;   declaration(D, Specs)
    ->  forall(pi_member(PI, Specs), check_declared(D, PI))
    ;   library_directive(D)
    ->  true
    ;   init_goal(D, _)
    ->  true
    ;   refuse(directive(D), 'not allowed in a program sent by a peer')
    ).

declaration(dynamic(S), S).
declaration(discontiguous(S), S).
declaration(multifile(S), S).
declaration(non_terminal(S), S).

pi_member(_, V) :- var(V), !, fail.
pi_member(PI, (A, B)) :- !, ( pi_member(PI, A) ; pi_member(PI, B) ).
pi_member(PI, [H|T]) :- !, ( pi_member(PI, H) ; pi_member(PI, T) ).
pi_member(_, []) :- !, fail.
pi_member(PI, PI).

check_declared(D, PI0) :-
    (   PI0 = M0:PI1 -> true ; M0 = '$program', PI1 = PI0 ),
    (   atom(M0), pred_indicator(PI1, F, A) -> M = M0
    ;   refuse(directive(D), 'not a predicate indicator')
    ),
    (   M == '$program'
    ->  (   D = multifile(_)
        ->  refuse(directive(D), 'declares a hook')
        ;   own_predicate(F/A)
        )
    ;   mobile_hook(M:F/A)
    ->  true
    ;   moved_hook(M:F/A, To)
    ->  refuse_moved(M:F/A, To)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  refuse(hook(Q:F/A), Why)
    ;   refuse(directive(D), 'declares a predicate of another module')
    ).

%   moved_hook(+Old, -New): the aggregation hooks were dfrl_agent's before
%   they moved to the module named for them. A method written for the old
%   module, whether it defines a hook, declares one or calls one, is
%   refused with the culprit moved_hook(Old, New), which names the new
%   predicate: the culprit (unlike the context) reaches the node that sent
%   the program (dfrl inject), so its message points there too.
moved_hook(dfrl_agent:F/A, dfrl_aggregation:F/A) :-
    mobile_hook(dfrl_aggregation:F/A).

refuse_moved(Old, New) :-
    refuse(moved_hook(Old, New), _).             % the culprit says it all

declared(D, F/A) :-
    declaration(D, Specs),
    pi_member(PI, Specs),
    pred_indicator(PI, F, A).

declared((A, B), PI) :-
    (   declared(A, PI) ; declared(B, PI) ).

%   Name/Arity, or Name//Arity of a non-terminal (Arity + 2 arguments).
pred_indicator(PI, F, A) :-
    nonvar(PI),
    (   PI = F/A
    ->  atom(F), integer(A)
    ;   PI = F//A0
    ->  atom(F), integer(A0),
        A is A0 + 2
    ).

library_directive(use_module(library(X))) :- safe_library(X).
library_directive(use_module(library(X), _)) :- safe_library(X).
library_directive(ensure_loaded(library(X))) :- safe_library(X).

%   initialization(G, main) would halt the node after G, the other
%   moments (restore, program, after_load) run G when the program
%   cannot be checked again: only now and after loading are allowed.
%   Both run after the program is loaded, under the agent bounds
%   (codeload.pl).
init_goal(initialization(G), G).
init_goal(initialization(G, now), G).

directive_init(D, G) :-
    (   init_goal(D, G)
    ;   D = (A, B),
        (   directive_init(A, G) ; directive_init(B, G) )
    ).

		 /*******************************
		 *     HOOKS: DEFAULT DENY	*
		 *******************************/

%!  hook_refusal(+Name/Arity, -Module, -Why) is semidet.
%
%   A program sent by a peer may not define Name/Arity, in its own
%   module or elsewhere (but for the mobile hooks), because the Prolog
%   system, a library or the node calls a predicate of that name (in
%   Module): SWI-Prolog looks several hooks up in `user` whether or not
%   they are declared (user:prolog_exception_hook/4 is not, in 9.0.4),
%   expansion hooks run in the module being loaded, and attribute hooks
%   in the module named by the attribute. Rather than a list alone, a
%   name is refused if
%
%     - it is one of the hooks that SWI-Prolog 9.0.4 calls by name
%       (called_by_name/1: its manual, its C core, and every
%       user:/prolog: hook its library and boot files declare, which
%       tests/platform/test_codeload.pl derives again from the
%       installed sources);
%     - `system` defines it (built-ins, system hooks such as
%       term_expansion/2);
%     - `prolog` or `user` defines or declares it (the node's own
%       predicates; programs sent by peers never load into `user`);
%     - any module of the process declares it multifile (a hook by
%       definition: sandbox:safe_primitive/1, node:platform_request/4);
%     - a library exports it (the autoload index, or a loaded library
%       module).

hook_refusal(F/A, Q, Why) :-
    atom(F), integer(A),
    functor(H, F, A),
    hook_refusal_(F/A, H, Q, Why),
    !.

hook_refusal_(F/A, _, Q, 'a hook the Prolog system or a library calls by name') :-
    called_by_name(Q:F/A).
hook_refusal_(F/A, _, system, 'a predicate of the Prolog system') :-
    current_predicate(system:F/A).
hook_refusal_(F/A, _, Q, 'a predicate or hook the node defines') :-
    member(Q, [user, prolog]),
    current_predicate(Q:F/A).                   % also declared dynamic or multifile
hook_refusal_(_, H, Q, 'a hook (declared multifile there)') :-
    current_predicate(_, Q:H),
    \+ program_or_agent_module(Q),
    predicate_property(Q:H, multifile).
hook_refusal_(F/A, _, Q, 'a predicate of a library') :-
    '$in_library'(F, A, Path),
    file_base_name(Path, Q).
hook_refusal_(_, H, Q, 'a predicate of a library') :-
    current_predicate(_, Q:H),
    module_property(Q, class(Class)),
    memberchk(Class, [library, system]),
    predicate_property(Q:H, exported).

%   (current_predicate/1,2 come first: predicate_property/2 of a name
%   that is not defined autoloads its library, and a program could make
%   the node load any library by naming it.)

program_or_agent_module(M) :-
    (   sub_atom(M, 0, _, _, 'dfrl_program://')
    ;   sub_atom(M, 0, _, _, 'dfrl_agent@')
    ;   scratch_module(M)
    ),
    !.

%!  called_by_name(?Module:Name/Arity) is nondet.
%
%   Hooks SWI-Prolog 9.0.4 calls by name (non-terminals Name//N are
%   given as Name/N+2). From its manual and C core: the exception,
%   trace, event, signal and undefined-procedure hooks, expansion,
%   portray, attribute hooks (called in the module named by the
%   attribute); then every user:Name/Arity and prolog:Name/Arity its
%   boot/ and library/ sources declare or call (grep of
%   `(user|prolog):Name/Arity` and `//Arity`; the test derives it again).

called_by_name(user:F/A) :- user_hook(F/A).
called_by_name(prolog:F/A) :- prolog_hook(F/A).
called_by_name(system:F/A) :- system_hook(F/A).
called_by_name(attribute:F/A) :- attribute_hook(F/A).

%   Looked up in user (boot/, library/, the C core).
user_hook(prolog_exception_hook/4).
user_hook(exception/3).
user_hook(message_hook/3).
user_hook(thread_message_hook/3).
user_hook(portray/1).
user_hook(portray_message/2).
user_hook(message_property/2).
user_hook(prolog_load_file/2).
user_hook(term_expansion/2).
user_hook(term_expansion/4).
user_hook(term_expansion/6).
user_hook(goal_expansion/2).
user_hook(goal_expansion/4).
user_hook(prolog_trace_interception/4).
user_hook(prolog_event_hook/1).
user_hook(prolog_predicate_name/2).
user_hook(prolog_clause_name/2).
user_hook(prolog_list_goal/1).
user_hook(prolog_stack_frame_property/2).
user_hook(resource/2).
user_hook(resource/3).
user_hook(file_search_path/2).
user_hook(library_directory/1).
user_hook(prolog_file_type/2).
user_hook(expand_query/4).
user_hook(expand_answer/2).
user_hook(url_path/2).
user_hook(generate_message_hook/3).
user_hook(portray_attvar/1).
user_hook(exception_hook/4).
user_hook(prolog_on_signal/2).
user_hook(prolog_alert_signal/2).
user_hook(message_prefix_hook/2).
user_hook(prolog_edit/1).
user_hook(prolog_stack_property/2).

%   Looked up in prolog (boot/, library/).
prolog_hook(prolog_exception_hook/5).
prolog_hook(alternate_syntax/4).
prolog_hook(assertion_failed/2).
prolog_hook(break_hook/7).
prolog_hook(build_config/5).
prolog_hook(build_environment/2).
prolog_hook(build_file/2).
prolog_hook(build_step/4).
prolog_hook(called_by/2).
prolog_hook(called_by/4).
prolog_hook(comment_hook/3).
prolog_hook(complete_input/4).
prolog_hook(confirm/2).
prolog_hook(console_color/2).
prolog_hook(debug_control_hook/1).
prolog_hook(debug_print_hook/3).
prolog_hook(deprecated/3).
prolog_hook(deprecated/4).
prolog_hook(doc_autolink_extension/2).
prolog_hook(doc_canonical_object/2).
prolog_hook(doc_category/3).
prolog_hook(doc_directory/1).
prolog_hook(doc_file_index_header/4).
prolog_hook(doc_file_title/5).
prolog_hook(doc_is_public_object/1).
prolog_hook(doc_links/4).
prolog_hook(doc_nav_tree/4).
prolog_hook(doc_object_footer/4).
prolog_hook(doc_object_href/2).
prolog_hook(doc_object_link/4).
prolog_hook(doc_object_page/4).
prolog_hook(doc_object_page_footer/4).
prolog_hook(doc_object_summary/4).
prolog_hook(doc_object_title/2).
prolog_hook(doc_page_header/4).
prolog_hook(doc_places_menu/3).
prolog_hook(doc_search_field/3).
prolog_hook(doc_url_expansion/3).
prolog_hook(doc_wiki_face/4).
prolog_hook(error_message/3).
prolog_hook(error_message/4).
prolog_hook(general_exception/2).
prolog_hook(generated_predicate/1).
prolog_hook(gpp_options/1).
prolog_hook(heartbeat/0).
prolog_hook(help_hook/1).
prolog_hook(history/2).
prolog_hook(history_line/2).
prolog_hook(hook/1).
prolog_hook(initialize_now/2).
prolog_hook(locate_clauses/2).
prolog_hook(make_hook/2).
prolog_hook(message/3).
prolog_hook(message/4).
prolog_hook(message_context/3).
prolog_hook(message_context/4).
prolog_hook(message_line_element/2).
prolog_hook(message_location/3).
prolog_hook(message_location/4).
prolog_hook(message_prefix_hook/2).
prolog_hook(meta_goal/2).
prolog_hook(no_autoload_module/1).
prolog_hook(obfuscate_identifiers/1).
prolog_hook(open_source_hook/3).
prolog_hook(portray/1).
prolog_hook(predicate_summary/2).
prolog_hook(quasi_quotation_syntax/2).
prolog_hook(rename_predicate/2).
prolog_hook(residual_goals/2).
prolog_hook(runtime_config/2).
prolog_hook(sandbox_allowed_clause/1).
prolog_hook(sandbox_allowed_directive/1).
prolog_hook(sandbox_allowed_expansion/1).
prolog_hook(sandbox_allowed_goal/1).
prolog_hook(show_profile_hook/1).
prolog_hook(show_profile_hook/2).
prolog_hook(theme/1).
prolog_hook(translate_bindings/5).
prolog_hook(translate_message/3).
prolog_hook(tripwire/2).
prolog_hook(url_expansion_hook/3).
prolog_hook(version_msg/1).
prolog_hook(xref_close_source/2).
prolog_hook(xref_open_source/2).
prolog_hook(xref_source_directory/2).
prolog_hook(xref_source_file/3).
prolog_hook(xref_source_identifier/2).
prolog_hook(xref_source_time/2).
prolog_hook(xref_update_syntax/2).

%   Looked up in system (expansion of every module's code).
system_hook(term_expansion/2).
system_hook(term_expansion/4).
system_hook(goal_expansion/2).
system_hook(goal_expansion/4).

%   Called as Attribute:Hook(...) when a variable with that attribute is
%   unified, copied or printed.
attribute_hook(attr_unify_hook/2).
attribute_hook(attribute_goals/3).
attribute_hook(attr_portray_hook/2).
attribute_hook(project_attributes/2).

		 /*******************************
		 *    THE AGENT API AS SAFE	*
		 *******************************/

%   Output to the agent's output.
:- multifile sandbox:safe_primitive/1, sandbox:safe_meta/2.

sandbox:safe_primitive(system:nl).
sandbox:safe_primitive(system:flush_output).
sandbox:safe_primitive(system:print(_)).
sandbox:safe_primitive(system:write(_)).
sandbox:safe_primitive(system:writeq(_)).
sandbox:safe_primitive(system:write_canonical(_)).
sandbox:safe_primitive(system:tab(_)).

sandbox:safe_meta(system:format(Out, Format, Args), Calls) :-
    memberchk(Out, [user_output, user_error]),
    sandbox:format_calls(Format, Args, Calls).
sandbox:safe_meta(M:G, Calls) :-
    platform_module(M),
    (   agent_api(M:G, Condition),
        call(Condition)
    ->  Calls = []
    ;   functor(G, F, A),
        (   moved_hook(M:F/A, To)
        ->  refuse_moved(M:F/A, To)
        ;   refuse(M:F/A, 'not part of the agent API')
        )
    ).

%   The platform's own modules: platform_pl/ and pybridge/. Nothing in
%   them is safe to a sandboxed caller unless agent_api/2 says so (the
%   sandbox's own analysis would, e.g., accept a predicate that asserts
%   into its own module, such as the one that sets the node's tokens).
:- dynamic platform_root/1.

:- prolog_load_context(directory, Dir),
   file_directory_name(Dir, Root),
   retractall(platform_root(_)),
   assertz(platform_root(Dir)),
   atom_concat(Root, '/pybridge', Py),
   assertz(platform_root(Py)).

platform_module(M) :-
    atom(M),
    module_property(M, file(File)),
    platform_root(Root),
    atom_concat(Root, '/', Prefix),
    sub_atom(File, 0, _, _, Prefix),
    !.

%!  agent_api(?Module:Goal, -Condition) is nondet.
%
%   Multifile: Module:Goal, a predicate of a platform module, may be
%   called by sandboxed code if Condition (called at check time)
%   succeeds. self(A) means: A is the agent itself.

agent_api(tartarus:move_agent(A, _), self(A)).
agent_api(tartarus:clone_agent(A, _, _), self(A)).
agent_api(tartarus:post_agent(_, _, _), true).
agent_api(tartarus:agent_post(_, _, _), true).
agent_api(tartarus:add_payload(A, _), self(A)).
agent_api(tartarus:remove_payload(A, _), self(A)).
agent_api(tartarus:purge_agent(A), self(A)).
agent_api(tartarus:execute_agent(A, _, _), self(A)).
agent_api(tartarus:execute_agent(A, _, _, _), self(A)).
agent_api(tartarus:get_tartarus_details(_, _), true).
agent_api(tartarus:isexist_agent(_, _, _), true).
agent_api(tartarus:list_agents, true).
agent_api(tartarus:list_agents(_), true).
agent_api(tartarus:list_agent, true).
agent_api(tartarus:list_agent(_), true).
agent_api(tartarus:agent_hop_times(_, _), true).
agent_api(tartarus:agent_hop_statistics(_, _), true).
agent_api(migration:agent_move(A, _, _), self(A)).
agent_api(migration:agent_clone(A, _, _, _), self(A)).
agent_api(messages:agent_post(_, _, _, _, _), true).
agent_api(messages:agent_post(_, _, _, _, _, _), true).
agent_api(messages:remote_agents(_, _, _), true).
agent_api(agents:current_agent(_), true).
agent_api(agents:agent_property(_, A, P), ( nonvar(P), agent_may_see(A, P) )).
agent_api(agents:agent_add_payload(_, A, _), self(A)).
agent_api(agents:agent_remove_payload(_, A, _), self(A)).
agent_api(agents:agent_add_facts(_, A, _), self(A)).
agent_api(agents:agent_exists(_, _), true).
agent_api(agents:agent_list(_, _), true).
agent_api(agents:agent_hop_times(_, _, _), true).
agent_api(node:current_node(_), true).
agent_api(node:node_property(_, P), ( nonvar(P), public_node_property(P) )).
agent_api(robot_resources:get_robot_table(_, _, _), true).
agent_api(robot_resources:get_robot_tables(_, _, _, _), true).
agent_api(robot_resources:set_robot_table(_, _, _), true).
agent_api(robot_resources:get_robot_params(_, _, _), true).
agent_api(robot_resources:set_robot_params(_, _, _), true).
agent_api(robot_resources:read_robot_table(_, _, _), true).
agent_api(robot_resources:read_robot_tables(_, _, _, _), true).
agent_api(robot_resources:write_robot_table(_, _, _), true).
agent_api(robot_resources:read_robot_params(_, _, _), true).
agent_api(robot_resources:write_robot_params(_, _, _), true).
agent_api(robot_resources:hosted_robot(_, _), true).
agent_api(dfrl_agent:dfrl_tour_event(A, _, _), self(A)).
agent_api(dfrl_agent:dfrl_tour_main(A, _), self(A)).
agent_api(dfrl_aggregation:dfrl_method(_), true).
%   The aggregation hooks: their clauses are the node's own or were
%   checked when a peer sent them (mobile_hook/1), so a method may build
%   on another (e.g. call the average's hooks).
agent_api(dfrl_aggregation:aggregate_init(_, _, _), true).
agent_api(dfrl_aggregation:aggregate_step(_, _, _, _), true).
agent_api(dfrl_aggregation:aggregate_final(_, _, _), true).
agent_api(dfrl_aggregation:method_uses_visits(_), true).
agent_api(dfrl_aggregation:method_applies(_, _), true).
agent_api(dfrl_aggregation:aggregate_tables(_, _, _), true).

%   An agent sees its own properties but its tokens; of other agents,
%   what list_agents/0 shows (never their module, payload or tokens).
agent_may_see(A, P) :-
    P \= tokens(_),
    (   self(A)
    ->  true
    ;   public_agent_property(P)
    ).

public_agent_property(handler(_)).
public_agent_property(kind(_)).
public_agent_property(status(_)).
public_agent_property(hops(_)).

public_node_property(address(_)).
public_node_property(link(_)).
public_node_property(id(_)).
public_node_property(bind(_)).

self(A) :-
    nonvar(A),
    catch(b_getval(code_safety_self, Self), _, fail),
    A == Self.
